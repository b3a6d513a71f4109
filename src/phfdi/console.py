"""The ``phfdi`` console script's entry point: :func:`phfdi.cli.main`, imported only once a Ctrl-C can be answered.

Importing the command line takes tenths of a second on a loaded machine; a Ctrl-C then used to print a
KeyboardInterrupt traceback from the import (``from phfdi.cli import main`` at the top of the generated script).
This module imports nothing else, so the script's own import of it is over within moments of the interpreter's
start; a Ctrl-C during the interpreter's start-up itself is Python's (before any of this package runs).

During the command line's imports a Ctrl-C is noted, not raised: raised inside an extension module's import it
can come out as another error (numpy's import turned it into an ImportError, "PyCapsule_Import could not import
module datetime", with a traceback), so it is answered once the imports are done. A Ctrl-C the shell told this
process to ignore (a background job) stays ignored.
"""

import signal
import sys


def main() -> int:
    interrupted: list[int] = []
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, lambda signum, _frame: interrupted.append(signum))
    try:
        from phfdi.cli import main as cli_main
    except KeyboardInterrupt:  # a Ctrl-C before the handler above was in place
        interrupted.append(signal.SIGINT)
    finally:
        if previous is not signal.SIG_IGN:
            signal.signal(signal.SIGINT, previous)
    if interrupted:
        print("phfdi: interrupted", file=sys.stderr)
        return 130
    return cli_main()
