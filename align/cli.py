"""The ``align`` console script (``align = "align.cli:main"``): the command line lives in
:mod:`align.commands`."""

from align.commands.main import main
from align.commands.parser import build_parser

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    import sys

    sys.exit(main())
