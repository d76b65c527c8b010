"""The image's build-time self-check: every module the service may load imports.

Run as the image's last build step, so a shared library a wheel needs from the
OS (libgomp for pinocchio and coal, Pango for WeasyPrint) fails the build, not
the first start, nor the first report PDF or survey upload hours later.
"""

import importlib

# The app and the packages it imports at start, then those it imports when a
# feature is first used (uploads, reports, recordings, Dask, PostgreSQL, Foxglove).
MODULES = [
    "server.app",
    "planners",
    "robots",
    "pinocchio",
    "coal",
    "ompl.geometric",
    "pymatching",
    "laspy",
    "lazrs",
    "pye57",
    "pyproj",
    "weasyprint",
    "matplotlib.pyplot",
    "PIL.Image",
    "mcap.writer",
    "rosbags.rosbag2",
    "foxglove",
    "psycopg",
    "psycopg_pool",
    "distributed",
    "viser",
]

for name in MODULES:
    importlib.import_module(name)
print(f"self-check: {len(MODULES)} modules import")
