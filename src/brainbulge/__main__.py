"""``python -m brainbulge``: the same as the ``brainbulge`` command."""

import sys

from brainbulge.cli import main

sys.exit(main())
