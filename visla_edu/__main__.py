"""The process's entry point: ``python -m visla_edu`` and the ``visla-edu`` console script.

Both run :func:`console_main`, which runs :func:`visla_edu.cli.main` (the commands' one error
boundary) and makes Ctrl-C end the process with exit status 130 at every moment after this
module starts, never by the signal itself.
"""

import signal
import sys

#: Exit status of Ctrl-C, as ``visla_edu.cli.EXIT_INTERRUPTED`` (here too: loading cli can be what is interrupted).
EXIT_INTERRUPTED = 130


def console_main():
    """Run the command line on ``sys.argv``; Ctrl-C at any moment gives exit status 130.

    The moments, and what covers each:

    * loading :mod:`visla_edu.cli` (done here, inside the boundary): one line, 130, nothing written;
    * parsing and the whole command, up to its last line: :func:`visla_edu.cli.main`'s boundary
      (one line, 130; files being written keep their previous content);
    * after :func:`~visla_edu.cli.main` returns, SIGINT is ignored. The command is complete then
      (every output written and reported), so a Ctrl-C during the interpreter's shutdown
      changes nothing and its status stands. Left to Python, it would raise KeyboardInterrupt
      outside any handler there (an uncaught KeyboardInterrupt ends the process by SIGINT:
      status -2 to a parent process, 130 in a shell, with a traceback), or, late in the
      shutdown, where Python restores the default action of SIGINT, the signal would kill it.

    Only the interpreter's own start-up, before this module runs, is not covered.

    Returns
    -------
    int
        :func:`visla_edu.cli.main`'s exit status, or 130.

    Raises
    ------
    SystemExit
        As :func:`visla_edu.cli.main` (argparse's usage errors and ``--help``, ``release --check``).
    """
    started = False
    try:
        try:
            from visla_edu.cli import main

            started = True
            return main()
        finally:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    except KeyboardInterrupt:  # while cli loaded, or between main's return and the line above
        if not started:
            print("visla-edu: interrupted (Ctrl-C) while starting; nothing was run", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(console_main())
