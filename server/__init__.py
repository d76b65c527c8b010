"""SteelPath service: FastAPI app, storage, planning jobs, scene, console, CLI."""

__version__ = "0.1.0"
