"""``python -m picopit``: the same as the ``picopit`` command."""

import sys

from .cli import main

sys.exit(main())
