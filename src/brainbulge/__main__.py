"""``python -m brainbulge.cli``."""

import sys

from brainbulge.cli import main

sys.exit(main())
