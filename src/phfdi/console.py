"""The ``phfdi`` console script's entry point: :func:`phfdi.cli.main`, imported only once a Ctrl-C can be answered.

Importing the command line takes tenths of a second on a loaded machine; a Ctrl-C then used to print a
KeyboardInterrupt traceback from the import (``from phfdi.cli import main`` at the top of the generated script).
This module imports nothing else, so the script's own import of it is over within moments of the interpreter's
start; a Ctrl-C during the interpreter's start-up itself is Python's (before any of this package runs).
"""

import sys


def main() -> int:
    try:
        from phfdi.cli import main as cli_main
    except KeyboardInterrupt:
        print("phfdi: interrupted", file=sys.stderr)
        return 130
    return cli_main()
