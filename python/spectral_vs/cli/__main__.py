"""``python -m spectral_vs.cli``."""

import sys

from spectral_vs.cli import main

sys.exit(main())
