"""Service settings from ``STEELPATH_*`` environment variables (pydantic-settings)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    """Every knob of a running SteelPath service.

    Each field reads ``STEELPATH_<NAME>`` (e.g. ``STEELPATH_DATA=/srv/steelpath``);
    the defaults are the embedded lab set-up of DESIGN §9.
    """

    model_config = SettingsConfigDict(env_prefix="STEELPATH_", extra="ignore")

    data: Path = Field(
        Path("./var"),
        description="data directory: the SQLite database (unless database_url selects "
        "PostgreSQL) and the .npy arrays (clouds, plan arrays), photos and uploads; with "
        "several servers on one PostgreSQL this must be one shared directory (e.g. an NFS "
        "or CephFS mount, or a shared volume) that every server and planning worker mounts",
    )
    host: str = Field("127.0.0.1", description="HTTP bind address of the API and console")
    port: int = Field(8000, ge=0, le=65535, description="HTTP port of the API and console")
    scene_port: int = Field(
        8081,
        ge=0,
        le=65535,
        description="port of the in-process viser scene (bound to 127.0.0.1; 0 disables it)",
    )
    foxglove_port: int = Field(
        0,
        ge=0,
        le=65535,
        description="port of the live Foxglove WebSocket server (always bound to 127.0.0.1; "
        "remote users connect through the authenticated proxy at /foxglove); 0 (the default) "
        "leaves it off",
    )
    max_upload_mb: float = Field(256.0, gt=0, description="largest accepted cloud upload (MiB)")
    disk_reserve_mb: float = Field(
        32.0,
        ge=0,
        le=1_000_000,
        description="free space on the data directory's file system kept for the audit "
        "log and the E-stop: a write request that would leave less answers 507 before it "
        "starts (the E-stop, clear-estop and deletions are never refused for space)",
    )
    token_file: Path | None = Field(
        None,
        description="where the first-start admin token is also written (mode 0600); "
        "the CLI reads its token from here when STEELPATH_TOKEN is unset",
    )
    job_mode: Literal["process", "thread"] = Field(
        "process", description="run planning jobs in worker processes or threads"
    )
    job_workers: int = Field(2, ge=1, le=64, description="concurrent planning jobs")
    job_preload: bool = Field(
        True,
        description="worker processes import every plan kind and load every robot when "
        "they start, so no operator's first plan waits ~2 s for it",
    )
    emulators: bool = Field(True, description="start one robot emulator per robot on serve")
    emulator_time_scale: float = Field(
        1.0,
        gt=0,
        le=1000,
        description="embedded emulators run motions this much faster than real time",
    )
    webhook_backoff_s: float = Field(
        2.0,
        gt=0,
        le=3600,
        description="first retry delay of a failed webhook delivery; doubled each attempt "
        "(capped at 300 s) up to webhook_max_attempts",
    )
    webhook_max_attempts: int = Field(
        8, ge=1, le=100, description="attempts before a webhook delivery is marked failed"
    )
    emulator_nice: int = Field(
        0,
        ge=-20,
        le=19,
        description="the embedded emulators' OS priority relative to the server's (an os.nice "
        "increment; below 0 needs root). An emulator stands in for a robot controller with a "
        "CPU of its own: ahead of the server (< 0) it takes CPU a real robot never would, the "
        "more so at a time scale of 10, where it handles ten times a real robot's command rate",
    )
    database_url: str | None = Field(
        None,
        description="postgresql://user:pass@host/db selects PostgreSQL as the store (shared by "
        "several servers and planning workers); unset keeps SQLite under the data directory",
    )
    dask_scheduler: str | None = Field(
        None,
        description="tcp://host:8786 sends planning jobs to that Dask cluster (its workers read "
        "and write through the shared store); unset keeps the local process pool",
    )
    dask_stuck_s: float = Field(
        600.0,
        gt=0,
        le=86400,
        description="a Dask worker whose plan has written no progress for this long is "
        "restarted and the plan re-run once (generous: a planner may go minutes between "
        "progress calls on a whole-span cloud)",
    )
    server_url: str | None = Field(
        None,
        description="this server's base URL as other servers sharing the store reach it "
        "(e.g. http://10.0.0.5:8000); unset: http://<host>:<port>",
    )
    robot_lease_s: float = Field(
        3.0,
        gt=0,
        le=60,
        description="how long a server's ownership of a robot link lasts without renewal; "
        "another server takes the robot over only after it has lapsed",
    )
    emulator_urls: dict[str, str] = Field(
        default_factory=dict,
        description="robot emulators run elsewhere, as JSON {robot: socket://host:port} "
        "(e.g. one container per robot in the scaled Docker set-up, reachable by every "
        "server); recorded in the store like embedded emulators' URLs, never over an "
        "operator's PUT /robots/{name}/connection",
    )
    orphan_plan_s: float = Field(
        10.0,
        gt=0,
        le=3600,
        description="a queued or planning plan whose server has sent no heartbeat for this "
        "long is adopted and planned again by another server sharing the store",
    )
    log_level: str = Field("info", description="uvicorn log level")
    access_log: bool = Field(
        False,
        description="log every HTTP request (off by default: a console polling robots writes "
        "thousands of lines, and each is a write on the server's event loop)",
    )

    @field_validator("emulator_urls")
    @classmethod
    def _socket_urls(cls, urls: dict[str, str]) -> dict[str, str]:
        for name, url in urls.items():
            host, _, port = url.removeprefix("socket://").rpartition(":")
            if not url.startswith("socket://") or not host or not port.isdigit():
                raise ValueError(f"emulator_urls[{name!r}] = {url!r}: expected socket://host:port")
        return urls

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)

    @property
    def disk_reserve_bytes(self) -> int:
        return int(self.disk_reserve_mb * 1024 * 1024)

    @property
    def db_path(self) -> Path:
        return self.data / "steelpath.sqlite3"


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
