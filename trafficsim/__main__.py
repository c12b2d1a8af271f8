"""``python -m trafficsim``."""

import sys

from trafficsim.cli import main

sys.exit(main())
