"""The command line: ``colourhs run`` (the whole workflow) and one subcommand per stage.

:mod:`colourhs.cli.parser` builds the parser and dispatches; :mod:`colourhs.cli.commands`
holds the stage commands it calls. Light on purpose: importing it loads none of the
stages' libraries.
"""

from colourhs.cli.parser import main

__all__ = ["main"]
