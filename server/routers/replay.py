"""Routes of issue #16 §3 (console replay) — being written."""

from __future__ import annotations

from fastapi import APIRouter

router = APIRouter()
