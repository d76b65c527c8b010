"""How much a run may bring back: bounds per execution and per capture.

Read from ``STEELPATH_CAPTURE_*`` environment variables (the same prefix as
:class:`server.settings.Settings`; a field of that name on the service's
settings wins), so both the web server and the robot-link service, which
inherits the environment, apply the same bounds.
"""

from __future__ import annotations

from typing import Any

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class CaptureLimits(BaseSettings):
    """Bounds on the captures stored with one execution."""

    model_config = SettingsConfigDict(env_prefix="STEELPATH_", extra="ignore")

    capture_max_per_execution: int = Field(
        500, ge=0, description="captures stored per execution; later ones are refused"
    )
    capture_max_points_per_execution: int = Field(
        50_000_000, ge=0, description="points stored per execution over all its captures"
    )
    capture_max_points: int = Field(
        5_000_000, ge=1, description="points of one capture; a larger one is refused"
    )


def capture_limits(settings: Any = None, **override: int) -> CaptureLimits:
    """The limits: ``override``, else a field of ``settings`` of the same name,
    else the environment, else the defaults."""
    values: dict[str, Any] = {}
    for name in CaptureLimits.model_fields:
        v = getattr(settings, name, None) if settings is not None else None
        if isinstance(v, int):
            values[name] = v
    values.update(override)
    return CaptureLimits.model_validate(values)
