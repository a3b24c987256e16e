"""``python -m colourhs``: the command line."""

import sys

from colourhs.cli import main

sys.exit(main())
