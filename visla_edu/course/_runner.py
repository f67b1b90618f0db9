"""Start the grading process of one submission with its limits, and read what it left.

:func:`run_submission` runs ``python -m visla_edu.course._grader_child REQUEST`` in a folder and process
group of its own (output to ``output.txt``), waits with the time limit and reads the outcome; a child
without one is reported as ``timeout`` (time limit) or ``crashed`` (a signal or an early exit).

**The limits**: the time limit, wall clock, for import, ``make_filter`` and every step together (counted
from the child's first ``progress``; then the whole group is killed); CPU seconds of that plus
:data:`CPU_MARGIN`; address space (None: no limit); :data:`FILE_LIMIT` bytes a file; no new processes or
threads. The child sets all but the first on itself (:func:`visla_edu.course._grader_child.limit_resources`).
"""

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ChildOutcome", "DEFAULT_TIME_LIMIT", "DEFAULT_MEMORY_LIMIT", "EXIT_STATUSES", "STARTUP_SECONDS",
           "FILE_LIMIT", "write_request", "wait_with_time_limit", "read_outcome", "run_submission"]

#: The default time limit (s; the module docstring).
DEFAULT_TIME_LIMIT = 600.0
#: The default memory limit (bytes of address space).
DEFAULT_MEMORY_LIMIT = 4 * 2**30
#: The folder that holds the ``visla_edu`` package: the child imports this very copy.
PACKAGE_PARENT = Path(__file__).resolve().parents[2]
#: Seconds the grading process may take to start (imports, loading the drive) before the time limit counts.
STARTUP_SECONDS = 120.0
#: Bytes any one file the grading process writes may reach (its output log included).
FILE_LIMIT = 256 * 2**20
#: CPU seconds the grading process may use beyond the time limit (its start-up and the outcome).
CPU_MARGIN = 60
#: How often the parent looks at the child (s).
_POLL_SECONDS = 0.05
#: What the parent reports when the child left no outcome (the child's own: ``_grader_child.STATUSES``).
EXIT_STATUSES = {
    "timeout": "ran past the time limit (wall clock) or its CPU seconds, and was stopped",
    "crashed": "the grading process ended without an outcome: killed by a signal, os._exit, a crash",
}
_SIGNALS = {
    "SIGXCPU": ("timeout", "used more CPU seconds than the time limit allows and was stopped (SIGXCPU)"),
    "SIGXFSZ": ("crashed", f"wrote more than {FILE_LIMIT // 2**20} MiB to one file or to its output, and was stopped "
                           "(SIGXFSZ)"),
    "SIGKILL": ("crashed", "was killed (SIGKILL: often the system running out of memory)"),
    "SIGSEGV": ("crashed", "crashed the Python process (SIGSEGV: a segmentation fault in compiled code)"),
}


@dataclass
class ChildOutcome:
    """What one submission's grading process reported, or how it ended.

    Fields as in ``outcome.json`` (:mod:`visla_edu.course._grader_child`); without it ``status`` is a key of
    :data:`EXIT_STATUSES` and ``seconds`` NaN. ``arrays``: ``estimate.npz``, ``frames`` rows each (or empty);
    ``output``: the last 4000 characters the process printed.
    """

    status: str
    message: str
    frames: int = 0
    seconds: float = float("nan")
    hidden_calls: list = field(default_factory=list)
    traceback: str = ""
    notes: list = field(default_factory=list)
    arrays: dict = field(default_factory=dict)
    output: str = ""


def write_request(folder, submission, drive_file, config, time_limit, memory_limit):
    """Write ``folder/request.json`` (``config`` as its ``to_dict()``) for the grading process; return its path."""
    request = {"submission": str(Path(submission).resolve()), "drive": str(drive_file), "config": config.to_dict(),
               "out": str(folder), "memory_limit": memory_limit, "cpu_limit": int(time_limit + CPU_MARGIN),
               "file_limit": FILE_LIMIT}
    path = folder / "request.json"
    path.write_text(json.dumps(request), encoding="utf-8")
    return path


def _kill_group(proc):
    """Kill the child and everything it started (its own process group)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        if hasattr(os, "killpg"):
            os.killpg(proc.pid, signal.SIGKILL)
        else:  # pragma: no cover - Windows
            proc.kill()


def wait_with_time_limit(proc, progress_file, time_limit):
    """Wait for ``proc``; kill its group ``time_limit`` s after ``progress_file`` appeared; ``(returncode, timed_out)``.

    Before the file appears (the grader's start-up) :data:`STARTUP_SECONDS` apply.
    """
    deadline = time.monotonic() + STARTUP_SECONDS
    counting = False
    while True:
        try:
            proc.wait(timeout=_POLL_SECONDS)
            _kill_group(proc)  # whatever it left behind
            return proc.returncode, False
        except subprocess.TimeoutExpired:
            pass
        now = time.monotonic()
        if not counting and progress_file.exists():
            counting, deadline = True, now + time_limit
        if now > deadline:
            _kill_group(proc)
            proc.wait()
            return proc.returncode, True


#: The variables of the grader's environment the child keeps (none of the teacher's paths or keys).
_KEPT_VARIABLES = ("PATH", "HOME", "LANG", "LC_ALL", "LC_CTYPE", "TMPDIR", "TEMP", "TMP", "SYSTEMROOT", "MPLCONFIGDIR")


def _child_environment():
    """A few system variables, this visla_edu first on the path, one BLAS thread."""
    env = {name: os.environ[name] for name in _KEPT_VARIABLES if name in os.environ}
    given = os.environ.get("PYTHONPATH", "")
    env["PYTHONPATH"] = os.pathsep.join([str(PACKAGE_PARENT)] + ([given] if given else []))
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="1",
               MPLBACKEND="Agg", PYTHONIOENCODING="utf-8")
    return env


def _where(progress, num_frames):
    """Where a time limit struck, from the child's ``progress`` text."""
    if progress.startswith("frame "):
        return f"at about frame {progress.split()[1]} of {num_frames}"
    return {"import": "while importing it", "make_filter": "in make_filter"}.get(progress, "in step()")


def _ended_without_outcome(returncode, timed_out, progress, time_limit, num_frames):
    """``(status, message)`` of a child that left no outcome."""
    if timed_out and progress is None:
        return "timeout", (f"the grader's start-up took more than {STARTUP_SECONDS:.0f} s (an overloaded machine?); "
                           "the submission did not run")
    if timed_out:
        return "timeout", f"ran past the time limit of {time_limit:g} s ({_where(progress, num_frames)})"
    if progress is None:
        return None, None  # the grader's own failure: see read_outcome
    if returncode < 0:
        name = signal.Signals(-returncode).name if -returncode in signal.valid_signals() else f"signal {-returncode}"
        return _SIGNALS.get(name, ("crashed", f"was stopped by {name}"))
    return "crashed", (f"ended with exit status {returncode} before the grader finished ({_where(progress, num_frames)}"
                       "; os._exit, or a crash: see output.txt)")


def _read_text(path, limit=None):
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    return text if limit is None else text[-limit:]


def read_outcome(folder, returncode, timed_out, time_limit, num_frames):
    """The :class:`ChildOutcome` of the grading process that ran in ``folder``.

    RuntimeError if the process failed before the submission ran: the grader's problem, not the submission's.
    """
    import numpy as np  # here: the command line imports this module to build its parser

    output = _read_text(folder / "output.txt", 4000) or ""
    try:
        reported = json.loads((folder / "outcome.json").read_text(encoding="utf-8"))
        outcome = ChildOutcome(**{key: reported[key] for key in ("status", "message", "frames", "seconds",
                                                                 "hidden_calls", "traceback", "notes")})
    except (OSError, ValueError, KeyError, TypeError):
        progress = _read_text(folder / "progress")
        status, message = _ended_without_outcome(returncode, timed_out, progress, time_limit, num_frames)
        if status is None:
            last = (output.strip().splitlines() or ["(nothing)"])[-1]
            raise RuntimeError(f"the grading process failed before the submission ran (exit status {returncode}); "
                               f"its last line: {last}")
        outcome = ChildOutcome(status, message)
    outcome.output = output
    with contextlib.suppress(OSError, ValueError), np.load(folder / "estimate.npz") as saved:
        outcome.arrays = {key: saved[key] for key in saved.files}  # else the default, {}
    outcome.frames = len(outcome.arrays.get("world_T_imu", ()))
    return outcome


def run_submission(submission, drive_file, config, folder, time_limit, memory_limit, num_frames):
    """Grade one submission in its own process, in the empty ``folder``; return its :class:`ChildOutcome`.

    ``drive_file``: the prepared drive without ground truth (:func:`visla_edu.data.save`); ``config``: the
    resolved FilterConfig; ``time_limit`` (s), ``memory_limit`` (bytes or None); ``num_frames``, for messages.
    """
    request = write_request(folder, submission, drive_file, config, time_limit, memory_limit)
    command = [sys.executable, "-m", "visla_edu.course._grader_child", str(request)]
    with open(folder / "output.txt", "wb") as log:
        proc = subprocess.Popen(command, cwd=folder, env=_child_environment(), stdin=subprocess.DEVNULL, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)
        try:
            returncode, timed_out = wait_with_time_limit(proc, folder / "progress", time_limit)
        except BaseException:  # Ctrl-C: never leave a submission running
            _kill_group(proc)
            proc.wait()
            raise
    return read_outcome(folder, returncode, timed_out, time_limit, num_frames)
