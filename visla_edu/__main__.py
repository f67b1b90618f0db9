"""The process's entry point: ``python -m visla_edu`` and the ``visla-edu`` console script.

Both run :func:`console_main` around :func:`visla_edu.cli.main` (the commands' one error boundary).
"""

import signal
import sys

#: Exit status of Ctrl-C, as ``visla_edu.cli.EXIT_INTERRUPTED`` (here too: loading cli can be what is interrupted).
EXIT_INTERRUPTED = 130


def console_main():
    """Run the command line on ``sys.argv``; return :func:`visla_edu.cli.main`'s exit status, or 130 on Ctrl-C.

    * Loading :mod:`visla_edu.cli` (done here, inside the boundary): one line, 130, nothing written.
    * Parsing and the whole command, up to its last line: :func:`visla_edu.cli.main`'s boundary (one
      line, 130; files being written keep their previous content).
    * After :func:`~visla_edu.cli.main` returns, SIGINT is ignored: the command is complete, so a
      Ctrl-C during the interpreter's shutdown changes nothing.

    Only the interpreter's own start-up, before this module runs, is not covered. SystemExit: as
    :func:`visla_edu.cli.main`.
    """
    started = False
    try:
        try:
            from visla_edu.cli import main

            started = True
            return main()
        finally:
            # Left to Python, a Ctrl-C in the shutdown would raise KeyboardInterrupt outside any handler (the
            # process then ends by SIGINT: status -2 to a parent, with a traceback), or, late in the shutdown
            # where Python restores SIGINT's default action, the signal would kill it.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    except KeyboardInterrupt:  # while cli loaded, or between main's return and the line above
        if not started:
            print("visla-edu: interrupted (Ctrl-C) while starting; nothing was run", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(console_main())
