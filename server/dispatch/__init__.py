"""Dispatch of approved plans to robots (DESIGN §3, §4, §7)."""

from server.dispatch.engine import DispatchEngine, DispatchError

__all__ = ["DispatchEngine", "DispatchError"]
