"""``python -m robots.emulator`` — same as ``steelpath emulate``."""

from robots.emulator.cli import main

raise SystemExit(main())
