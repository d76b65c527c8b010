"""Placeholder replaced by the foundation CLI."""


def main() -> None:  # pragma: no cover
    raise SystemExit("steelpath CLI not built yet")
