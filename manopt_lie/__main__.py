"""``python -m manopt_lie``: the ``manopt-lie`` command line."""

import sys

from .cli import main

sys.exit(main())
