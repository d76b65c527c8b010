"""Plan kinds used only by the tests (loaded with STEELPATH_EXTRA_KINDS)."""

from __future__ import annotations

import os
import time

from pydantic import BaseModel, Field

from server.kinds.base import Check, KindOutput, PlanKind


class Params(BaseModel):
    seconds: float = Field(30.0, description="how long the slow kind keeps reporting progress")
    mode: str = Field("slow", description="slow | raise | crash | nan | hang")


def run(p: Params, ctx) -> KindOutput:
    if p.mode == "raise":
        raise RuntimeError("planner blew up on purpose")
    if p.mode == "crash":
        os._exit(3)  # a native crash in the worker process
    if p.mode == "nan":
        return KindOutput(result={"x": float("nan")})
    if p.mode == "hang":  # a planner stuck without a progress call for ``seconds``
        time.sleep(p.seconds)
        return KindOutput(result={"ticks": 0}, checks=[Check(name="ok", passed=True)])
    t0 = time.monotonic()
    i = 0
    while time.monotonic() - t0 < p.seconds:
        i += 1
        ctx.progress(min((time.monotonic() - t0) / p.seconds, 0.99), f"tick {i}")
        time.sleep(0.02)
    return KindOutput(result={"ticks": i}, checks=[Check(name="ok", passed=True)])


KIND = PlanKind(name="test.job", title="test job", params_model=Params, run=run)
