"""The machinery every check shares: calling the student's code, comparing, failure messages.

A failure message's first line has at most 79 characters, the later ones are wrapped at 79:
``nbgrader validate`` indents each line of a traceback by 4 and cuts it at 87 characters,
``AssertionError: `` included, so the later lines show whole and the first its first 67.
"""

import functools
import os
import textwrap

import numpy as np

from visla_edu.course.checks import _hiding

__all__ = [
    "exercise_check",
    "SEED",
    "HIDDEN_SEED_VARIABLE",
    "rng",
    "ok",
    "fmt",
    "fail",
    "wrap_message",
    "student",
    "as_array",
    "close",
    "compare",
    "student_or_reference",
]

#: Seed of the visible cases: a check gives the same verdict every time.
SEED = 276
#: Environment variable with the seed of the hidden cases (a teacher may set a private one).
HIDDEN_SEED_VARIABLE = "VISLA_EDU_HIDDEN_SEED"
_DEFAULT_HIDDEN_SEED = 1827


def exercise_check(check):
    """Decorator of the public checks: failures show the message, not the checks' own frames.

    An ``AssertionError`` or ``NotImplementedError`` without a ``__cause__`` is raised again ``from None``,
    its message wrapped by :func:`wrap_message`; one with a cause (a crash of the student's code, with
    its traceback) and any other exception propagate unchanged.
    """

    @functools.wraps(check)
    def run(fn, hidden=False):
        try:
            return check(fn, hidden=hidden)
        except (AssertionError, NotImplementedError) as err:
            if err.__cause__ is not None:
                raise
            raise type(err)(wrap_message(str(err))) from None

    return run


def _hidden_seed():
    text = os.environ.get(HIDDEN_SEED_VARIABLE, "").strip()
    if not text:
        return _DEFAULT_HIDDEN_SEED
    try:
        seed = int(text)
    except ValueError:
        seed = -1
    if seed < 0:  # numpy's generators take non-negative seeds only
        raise ValueError(f"{HIDDEN_SEED_VARIABLE} must be a non-negative integer, got {text!r}: unset it or "
                         "set it to a number such as 4711")
    return seed


def rng(hidden=False):
    """A new generator seeded with :data:`SEED`, or if ``hidden`` with :data:`HIDDEN_SEED_VARIABLE`'s integer.

    ``ValueError`` if that variable is not a non-negative integer; unset or empty: a built-in seed.
    """
    return np.random.default_rng(_hidden_seed() if hidden else SEED)


def ok(message, hidden=False):
    """Print the success line ``"\u2713 {message}"`` of a check; nothing if ``hidden``."""
    if not hidden:
        print(f"\u2713 {message}")


def fmt(x):
    """Text of an input in a failure message: a function's name, a ``repr``, <= 8 values on one line, or the shape."""
    if callable(x):
        return getattr(x, "__name__", "a function")
    arr = np.asarray(x)
    if arr.dtype == object:
        return repr(x)
    if arr.size <= 8:
        return np.array2string(arr, precision=6, separator=", ", suppress_small=False).replace("\n", "")
    return f"an array of shape {arr.shape}"


def wrap_message(text, details=()):
    """``text``, then the lines of ``details`` (empty ones skipped): the first line at most 79 characters (cut at
    a space), every later line wrapped at 79 (unchanged if already so)."""
    limit = _hiding.MAX_FIRST_LINE
    first, _, rest = text.partition("\n")
    if len(first) > limit:
        cut = first.rfind(" ", 0, limit + 1)
        cut = cut if cut > limit // 2 else limit
        first, rest = first[:cut].rstrip(), (first[cut:].strip() + ("\n" + rest if rest else ""))
    lines = [first]
    for part in (rest, *details):
        for line in part.split("\n") if part else ():
            lines.extend([line] if len(line) <= limit else textwrap.wrap(line, limit, break_on_hyphens=False))
    return "\n".join(lines)


def fail(name, hint, *details):
    """An ``AssertionError`` (to be raised): ``"{name}: {first line of hint}"``, then the details.

    ``name``: the student's function ("" if ``hint`` names it); ``hint``: the mistake in a few words, then
    the explanation; ``details``: further lines (empty ones skipped). Wrapped as by :func:`wrap_message`.
    """
    return AssertionError(wrap_message(f"{name}: {hint}" if name else hint, details))


def _materialize(out, name):
    """The student's output as float arrays (tuples stay tuples), converted while guarded: nothing lazy runs later."""
    if isinstance(out, tuple):
        return tuple(_materialize(item, name) for item in out)
    try:
        return _float64(np.array(out), name)
    except _hiding.LibraryFunctionHidden as err:
        raise fail("", str(err)) from None
    except (TypeError, ValueError) as err:
        if isinstance(out, list):
            return [_materialize(item, name) for item in out]
        raise fail(name, f"the result is not a numeric array ({type(out).__name__})", str(err)) from None


def _float64(arr, name):
    """``arr`` as float64, failing if complex (beyond rounding) or single precision, which ``dtype=float`` hides."""
    if arr.dtype.kind in "fc" and np.finfo(arr.dtype).eps > np.finfo(float).eps:
        raise fail(name, f"the result is {arr.dtype} (single precision): compute in float64",
                   f"{arr.dtype} keeps about {np.finfo(arr.dtype).precision} digits; the checks compare "
                   "to 1e-7 or better. Leave out dtype=np.float32 (numpy's default is float64).")
    if arr.dtype.kind == "c":
        imag, real = np.abs(arr.imag), np.abs(arr.real)
        if np.max(imag, initial=0.0) > 1e-9 * max(1.0, float(np.max(real, initial=0.0))):
            raise fail(name, "the result is complex: it has imaginary parts",
                       f"the largest is {np.max(imag):.3g}; the result must be real (an expm, eig or "
                       "sqrt of a negative number may have made it complex).")
        arr = arr.real
    return arr.astype(float)


def _raised_elsewhere(fn, err):
    """Name of the function that raised ``err`` if not ``fn`` (a stub that ``fn`` calls), else None."""
    code = getattr(getattr(fn, "__func__", fn), "__code__", None)
    tb = err.__traceback__
    if code is None or tb is None:
        return None
    while tb.tb_next is not None:
        tb = tb.tb_next
    raised = tb.tb_frame.f_code
    own = raised is code or raised.co_name == getattr(fn, "__name__", None)  # (or fn wraps it)
    return None if own else raised.co_name


class _Student:
    """The student's function, called with the library's versions hidden and state guarded."""

    def __init__(self, fn, name, hide):
        self.fn, self.name, self.hide = fn, name, tuple(hide)

    def _run(self, args, kwargs):
        """Call the student's function; turn its exceptions into readable failures."""
        try:
            return self.fn(*args, **kwargs)
        except NotImplementedError as err:
            other = _raised_elsewhere(self.fn, err)
            if other:
                raise NotImplementedError(str(fail(
                    "", f"{self.name} calls {other}, which is not implemented yet",
                    f"(it raised NotImplementedError: {err})",
                    f"write {other} first (or use the library's version where the exercise allows it), "
                    "run its cell, then run this check again"))) from None
            raise NotImplementedError(
                f"{self.name} is not implemented yet\nreplace the `raise NotImplementedError` line in "
                "the exercise cell above with your code, run that cell, then run this check again") from None
        except _hiding.LibraryFunctionHidden as err:
            raise fail("", str(err), f"(while calling {self.name}({_shown(args)}))") from None
        except Exception as err:  # noqa: BLE001 - any crash is a failed exercise with a message
            raise fail(self.name, f"raised {type(err).__name__}: {err}",
                       f"when called as {self.name}({_shown(args)})") from err

    def __call__(self, *args, **kwargs):
        args, kwargs = _private_copy(args), _private_copy(kwargs)
        with _hiding.guard(self.hide, self.name):
            return _materialize(self._run(args, kwargs), self.name)


def _private_copy(value):
    """``value`` with its arrays copied (also in tuples, lists, dicts): in-place updates leave the reference alone."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, tuple) and hasattr(value, "_fields"):  # a namedtuple
        return type(value)(*(_private_copy(v) for v in value))
    if isinstance(value, (tuple, list)):
        return type(value)(_private_copy(v) for v in value)
    if isinstance(value, dict):
        return {k: _private_copy(v) for k, v in value.items()}
    return value


def _shown(args):
    return ", ".join(fmt(a) for a in args)


def student(fn, name, hide=()):
    """Wrap the student's ``fn``: calls hide ``hide`` (library functions) and guard the library.

    The wrapper copies ``fn``'s arguments and returns its output as float arrays; ``NotImplementedError``
    for a stub, ``AssertionError`` for a crash, a call to a hidden function or a change to visla_edu.
    """
    return _Student(fn, name, hide)


def as_array(out, name, shape, what="result"):
    """``out`` as a float array of ``shape``, or a failure naming ``name`` and ``what`` (e.g. ``"pose"``).

    Its hint says when ``out`` is not numeric, is the transpose or has the right number of entries.
    """
    try:
        arr = np.asarray(out, dtype=float)
    except (TypeError, ValueError) as err:
        raise fail(name, f"the {what} is not a numeric array ({type(out).__name__})", str(err)) from None
    shape = tuple(shape)
    if arr.shape != shape:
        sizes = f"got shape {arr.shape}, expected {shape}"
        if arr.shape == shape[::-1] and len(shape) >= 2:
            raise fail(name, f"wrong shape of the {what}: it is transposed",
                       f"{sizes}: visla-edu is time/row-major, one row per point or frame")
        if arr.size == int(np.prod(shape)):
            raise fail(name, f"wrong shape of the {what}", f"{sizes}: same number of entries, reshape")
        raise fail(name, f"wrong shape of the {what}", sizes)
    return arr


def close(a, b, rtol, atol):
    """True if ``a`` and ``b`` have one shape and ``|a - b| <= atol + rtol |b|`` (NaN equal to NaN)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=rtol, atol=atol, equal_nan=True))


def _distance(a, b):
    """Largest absolute difference of two same-shaped arrays (inf if they differ in shape or NaN)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape:
        return np.inf
    difference = np.abs(a - b)
    return float(np.max(difference, initial=0.0)) if np.all(np.isfinite(difference)) else np.inf


def _matching_variant(got, variants, rtol, atol, expected=None):
    """The hint of the variant closest to ``got`` among those matching it, or None (see :func:`compare`).

    Not the first: at a tiny angle ``R^T``, ``V^T v`` and ``v`` all match each other and the answer.
    """
    best, best_distance = None, np.inf
    for hint, variant in variants:
        try:
            wrong = variant()
        except Exception:  # noqa: BLE001 - a variant that cannot be computed just does not match
            continue
        if close(got, wrong, max(rtol, 1e-6), max(atol, 1e-8)):
            distance = _distance(got, wrong)
            if distance < best_distance:
                best, best_distance = hint, distance
    if best is not None and expected is not None and not best_distance < _distance(got, expected):
        return None
    return best


def compare(name, got, expected, where, variants=(), rtol=1e-7, atol=1e-9, nan_hint="", extra=None):
    """Raise an ``AssertionError`` with the most specific hint if ``got`` differs from ``expected`` (:func:`close`).

    The hint, in order: "NaN or inf" and ``nan_hint`` if ``got`` has them and ``expected`` not; the
    matching variant; ``extra(got)``, a hint or "" from a property of the output (e.g. "not a
    rotation"); else none, and the message shows both arrays.

    Parameters
    ----------
    name, where : str
        The message's first word (the student's function) and its second line (the input).
    variants : sequence of (hint, callable)
        Each callable returns the output of one deliberate mistake on the same input (one that
        raises is skipped). Of those matching ``got`` to at least ``rtol = 1e-6``, ``atol = 1e-8``,
        the closest names the mistake, if ``got`` is closer to it than to ``expected``. A hint's
        first line is short.
    """
    if close(got, expected, rtol, atol):
        return
    expected = np.asarray(expected, dtype=float)
    if not np.all(np.isfinite(got)) and np.all(np.isfinite(expected)):
        raise fail(name, f"NaN or inf {nan_hint or 'in the result'}", where)
    hint = _matching_variant(got, variants, rtol, atol, expected) or (extra(got) if extra is not None else "")
    if hint:
        raise fail(name, hint, where)
    raise fail(name, "wrong values (no known mistake matches)", where,
               f"expected:\n{np.array2string(expected, precision=6)}",
               f"got:\n{np.array2string(np.asarray(got), precision=6)}")


def _close_nested(got, expected, rtol=1e-5, atol=1e-7):
    """:func:`close` that also compares tuples and lists (e.g. ``(mean, covariance)``) entry by entry."""
    if isinstance(expected, (tuple, list)):
        return (isinstance(got, (tuple, list)) and len(got) == len(expected)
                and all(_close_nested(g, e, rtol, atol) for g, e in zip(got, expected)))
    return close(got, expected, rtol, atol)


def student_or_reference(student_fn, reference_fn, *probe_args, name=None):
    """``student_fn`` if it runs on ``probe_args`` and agrees with ``reference_fn`` (same signature), else the latter.

    So that an unfinished exercise never blocks a notebook's later cells. The outputs (arrays, or
    tuples and lists of them) must agree to ``rtol = 1e-5``, ``atol = 1e-7``; any exception (e.g. a
    stub's) counts as disagreement. Prints ``"using your {name}"`` or ``"using the library's {name}
    (yours is not finished or disagrees)"``, ``name`` by default ``student_fn.__name__``.
    """
    name = name or getattr(student_fn, "__name__", "your function")
    try:
        agrees = _close_nested(student_fn(*probe_args), reference_fn(*probe_args))
    except Exception:  # noqa: BLE001 - stubs raise NotImplementedError, broken code anything
        agrees = False
    if agrees:
        print(f"using your {name}")
        return student_fn
    print(f"using the library's {name} (yours is not finished or disagrees)")
    return reference_fn
