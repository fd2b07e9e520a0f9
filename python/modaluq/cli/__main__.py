"""``python -m modaluq.cli``."""

import sys

from . import main

sys.exit(main())
