"""The process that runs one submission: ``python -m visla_edu.course._grader_child REQUEST.json``.

Started by :mod:`visla_edu.course._runner`: loads the request's drive and config, lowers its limits
(:func:`limit_resources`), hides the library (:mod:`visla_edu.course._sandbox`), then imports the
submission, calls ``make_filter(dataset, config)`` and steps once per frame (:func:`check_record`),
writing ``progress`` (``import``, ``make_filter``, ``frame N``). It leaves:

* ``estimate.npz``, the k frames done: ``world_T_imu`` (k, 4, 4), ``pose_cov`` (k, 6, 6), ``nis``,
  ``nis_dof``, ``step_seconds`` (k,);
* ``outcome.json``: ``status`` (a key of :data:`STATUSES`), ``message`` (one line, without the submission's
  name), ``frames``, ``seconds`` (the submission's own), ``hidden_calls``, ``traceback`` (``""`` if none), ``notes``.
"""

import json
import sys
import time
import traceback
import types
from pathlib import Path

import numpy as np

from visla_edu import data, validation
from visla_edu.course import _sandbox
from visla_edu.filters import FilterConfig, StepRecord

__all__ = ["STATUSES", "main", "check_record", "limit_resources"]

#: What the child reports, with what each status means (the parent adds ``timeout`` and ``crashed``).
STATUSES = {
    "ok": "ran every frame; every record was a valid StepRecord",
    "refused": "called a visla_edu function that is hidden while it is graded",
    "syntax-error": "the file is not valid Python",
    "import-error": "the file could not be imported, or defines no make_filter(dataset, config)",
    "raised": "make_filter or step() raised an exception",
    "out-of-memory": "ran out of memory (the grader's memory limit)",
    "wrong-type": "make_filter or step() returned something else than the interface asks",
    "non-finite": "a pose or its covariance had NaN or inf",
    "not-se3": "a pose was not a rigid transform [[R, p], [0, 0, 0, 1]]",
}


class _Failure(Exception):
    """A submission's failure the child names itself: ``status`` and a one-line message."""

    def __init__(self, status, message):
        super().__init__(message)
        self.status = status


def limit_resources(request):
    """Lower this process's limits for good (Linux and macOS); return notes on those that could not be set.

    ``request``: ``memory_limit`` (bytes, or None), ``cpu_limit`` (s), ``file_limit`` (bytes).
    """
    try:
        import resource
    except ImportError:
        return ["no resource limits on this system (the resource module is missing)"]
    limits = [("RLIMIT_CPU", request["cpu_limit"]), ("RLIMIT_FSIZE", request["file_limit"]),
              ("RLIMIT_AS", request["memory_limit"]), ("RLIMIT_NPROC", 0)]
    notes = []
    for name, value in limits:
        if value is None or not hasattr(resource, name):
            continue
        which = getattr(resource, name)
        hard = resource.getrlimit(which)[1]
        value = int(value) if hard == resource.RLIM_INFINITY else min(int(value), hard)
        try:
            resource.setrlimit(which, (value, value))
        except (ValueError, OSError) as err:
            notes.append(f"could not set {name} to {value}: {err}")
    return notes


def _progress(out, text):
    """Overwrite ``out/progress`` with ``text`` (for a time limit's message)."""
    (out / "progress").write_text(text)


def _import_submission(path):
    """The submission's module and its ``make_filter``; :class:`_Failure` for a syntax or import error."""
    source = Path(path).read_text(encoding="utf-8", errors="replace")
    try:
        code = compile(source, str(path), "exec")
    except (SyntaxError, ValueError) as err:
        where = f" at line {err.lineno}" if getattr(err, "lineno", None) else ""
        raise _Failure("syntax-error", f"is not valid Python{where}: {getattr(err, 'msg', err)}") from None
    module = types.ModuleType("submission")
    module.__file__ = str(path)
    sys.modules["submission"] = module
    try:
        exec(code, vars(module))  # noqa: S102 - running the submission is the grader's job
    except _sandbox.SubmissionUsedLibrary:
        raise
    except Exception as err:  # noqa: BLE001 - any error of the submission's import is its failure
        raise _Failure("import-error", f"failed to import: {_describe(err, path)}") from err
    make_filter = getattr(module, "make_filter", None)
    if not callable(make_filter):
        raise _Failure("import-error", "defines no make_filter(dataset, config) function")
    return make_filter


def _describe(err, path):
    """``Type: message (line N of file.py)``, one line, N the submission's last line in the traceback."""
    try:
        text = " ".join(str(err).split())
    except Exception:  # noqa: BLE001 - a submission's exception whose str() fails
        text = "(its message could not be read)"
    text = f"{type(err).__name__}: {text}" if text else type(err).__name__
    lines = [frame.lineno for frame in traceback.extract_tb(err.__traceback__) if frame.filename == str(path)]
    where = f" (line {lines[-1]} of {Path(path).name})" if lines else ""
    return f"{text[:300]}{where}"


def _traceback_text(err, path):
    """The traceback of the submission's error from its first frame in the submission's file."""
    tb = err.__traceback__
    while tb is not None and tb.tb_frame.f_code.co_filename != str(path):
        tb = tb.tb_next
    return "".join(traceback.format_exception(type(err), err, tb or err.__traceback__))


def check_filter(flt):
    """Raise :class:`_Failure` ``wrong-type`` unless ``flt`` has the stepper's ``config`` and ``step()``."""
    kind = type(flt).__name__
    if not callable(getattr(flt, "step", None)):
        raise _Failure("wrong-type", f"make_filter returned a {kind} without a step() method (the interface: "
                                     "an object with config and step(), see PROJECT.md)")
    if not isinstance(getattr(flt, "config", None), FilterConfig):
        raise _Failure("wrong-type", f"make_filter returned a {kind} whose config is not the FilterConfig it "
                                     "was given (keep it as the attribute config)")


def check_record(rec, t):
    """The pose (4, 4), covariance (6, 6), NIS and its dof of frame ``t``'s record, checked.

    :class:`_Failure` ``wrong-type``, ``non-finite`` or ``not-se3`` (to :data:`visla_edu.validation.POSE_RIGID_TOL`).
    """
    if not isinstance(rec, StepRecord):
        raise _Failure("wrong-type", f"step() returned a {type(rec).__name__} at frame {t}, not a "
                                     "visla_edu.filters.StepRecord")
    if isinstance(rec.t, bool) or not isinstance(rec.t, (int, np.integer)) or rec.t != t:
        raise _Failure("wrong-type", f"step() call {t + 1} returned record.t = {rec.t!r}; frames go 0, 1, 2, ..., "
                                     "one per call")
    try:
        pose = np.asarray(rec.world_T_imu, dtype=float)
        cov = np.asarray(rec.pose_cov, dtype=float)
        nis, dof = float(rec.nis), int(rec.nis_dof)
    except (TypeError, ValueError) as err:
        raise _Failure("wrong-type", f"the record of frame {t} holds something else than numbers ({err})") from None
    if pose.shape != (4, 4) or cov.shape != (6, 6):
        raise _Failure("wrong-type", f"the record of frame {t} has world_T_imu of shape {pose.shape} and pose_cov of "
                                     f"shape {cov.shape}; expected (4, 4) and (6, 6)")
    for what, value in (("pose world_T_imu", pose), ("pose covariance pose_cov", cov)):
        if not np.isfinite(value).all():
            raise _Failure("non-finite", f"returned a non-finite {what} at frame {t} (NaN or inf)")
    if validation.nonrigid_frames(pose[None], validation.POSE_RIGID_TOL)[0][0]:
        raise _Failure("not-se3", f"returned a pose that is not in SE(3) at frame {t} "
                                  f"({validation.rigid_detail(pose, validation.POSE_RIGID_TOL)})")
    return pose, cov, (nis if dof > 0 else np.nan), max(dof, 0)


class _Trace:
    """The records of the frames done so far (for ``estimate.npz``)."""

    def __init__(self, num_frames):
        self.done = 0
        self.world_T_imu = np.full((num_frames, 4, 4), np.nan)
        self.pose_cov = np.full((num_frames, 6, 6), np.nan)
        self.nis = np.full(num_frames, np.nan)
        self.nis_dof = np.zeros(num_frames, dtype=np.int64)
        self.step_seconds = np.zeros(num_frames)

    def arrays(self):
        k = self.done
        return {"world_T_imu": self.world_T_imu[:k], "pose_cov": self.pose_cov[:k], "nis": self.nis[:k],
                "nis_dof": self.nis_dof[:k], "step_seconds": self.step_seconds[:k]}


def _step_all(flt, trace, out):
    """Step ``flt`` over every frame into ``trace``, checking each record."""
    shown = time.monotonic()
    for t in range(len(trace.nis)):
        if time.monotonic() - shown > 0.5:
            _progress(out, f"frame {t}")
            shown = time.monotonic()
        start = time.perf_counter()
        rec = flt.step()
        trace.step_seconds[t] = time.perf_counter() - start
        trace.world_T_imu[t], trace.pose_cov[t], trace.nis[t], trace.nis_dof[t] = check_record(rec, t)
        trace.done = t + 1


def _run_submission(path, dataset, config, trace, out):
    """Import, build and step the submission; return ``(status, message, traceback text)``."""
    phase = "while importing it"
    try:
        _progress(out, "import")
        make_filter = _import_submission(path)
        phase = "in make_filter"
        _progress(out, "make_filter")
        flt = make_filter(dataset, config)
        check_filter(flt)
        phase = "in step()"
        _step_all(flt, trace, out)
    except _Failure as failure:
        cause = failure.__cause__
        return failure.status, str(failure), "" if cause is None else _traceback_text(cause, path)
    except _sandbox.SubmissionUsedLibrary as err:
        return "refused", (f"called {err.hidden} {phase}{_frame(phase, trace)}, which is hidden while it is graded "
                           "(PROJECT.md, 'What you may use')"), ""
    except MemoryError as err:
        return "out-of-memory", f"ran out of memory {phase}{_frame(phase, trace)} ({_describe(err, path)})", ""
    except (Exception, SystemExit) as err:  # noqa: BLE001 - the submission's error, whatever it is
        return "raised", f"{_describe(err, path)} {phase}{_frame(phase, trace)}", _traceback_text(err, path)
    return "ok", f"ran {trace.done} frames", ""


def _refused_first(status, message):
    """A hidden call decides the outcome, whatever came after it (the submission may have caught it)."""
    if not _sandbox.HIDDEN_CALLS or status == "refused":
        return status, message
    first = _sandbox.HIDDEN_CALLS[0]
    what = f"tried to {first}" if first.startswith("import ") else f"called {first}"
    after = "and went on when it raised" if status == "ok" else f"then {message}"
    return "refused", f"{what}, which is hidden while it is graded, {after}"


def _frame(phase, trace):
    return f" at frame {trace.done}" if phase == "in step()" else ""


def _load(request):
    """The drive and the settings of the request."""
    dataset = data.load(request["drive"])
    settings = {k: tuple(v) if isinstance(v, list) else v for k, v in request["config"].items()}
    return dataset, FilterConfig(**settings)


def main(argv=None):
    """Run the submission of the request file ``argv[0]``; write the outcome; return 0 (whatever the submission did)."""
    argv = sys.argv[1:] if argv is None else argv
    request = json.loads(Path(argv[0]).read_text(encoding="utf-8"))
    out = Path(request["out"])
    dataset, config = _load(request)
    trace = _Trace(dataset.num_frames)
    notes = limit_resources(request)
    _sandbox.hide_library()
    _sandbox.block_imports()
    start = time.perf_counter()
    status, message, trace_text = _run_submission(request["submission"], dataset, config, trace, out)
    status, message = _refused_first(status, message)
    seconds = time.perf_counter() - start
    with open(out / "estimate.npz", "wb") as f:
        np.savez(f, **trace.arrays())
    outcome = {"status": status, "message": message, "frames": trace.done, "seconds": seconds,
               "hidden_calls": list(dict.fromkeys(_sandbox.HIDDEN_CALLS)), "traceback": trace_text, "notes": notes}
    (out / "outcome.json").write_text(json.dumps(outcome), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
