"""``python -m server.linkservice``: the robot-link service (started by ``steelpath serve``)."""

import sys

from server.linkservice.service import main

sys.exit(main())
