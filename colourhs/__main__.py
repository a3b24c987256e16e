"""``python -m colourhs``: the command line."""

import sys

from colourhs.cli.parser import main

sys.exit(main())
