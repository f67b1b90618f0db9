"""The machinery every check shares: calling the student's code, comparing, failure messages.

A failure is an ``AssertionError`` whose **first line** (at most 79 characters) names the
mistake in its first words; the input, the explanation and the numbers follow on later lines,
wrapped at 79 characters. (``nbgrader validate`` indents each line of a traceback by 4 and cuts
it at 87 characters, ``AssertionError: `` included, so the later lines show whole and the first
one shows its first 67 characters.)
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

    A failure found by a comparison is re-raised from the check itself, so a notebook (and
    ``nbgrader validate``) shows the student's cell and the message, not the lines of the
    checks. A crash of the student's code keeps its chained traceback (where it crashed).

    Parameters
    ----------
    check : callable
        ``check(fn, hidden=False)``, raising ``AssertionError`` or ``NotImplementedError`` when
        the student's function ``fn`` fails.

    Returns
    -------
    callable
        ``run(fn, hidden=False)`` with ``check``'s name and docstring (:func:`functools.wraps`):
        it returns what ``check`` returns; an ``AssertionError`` or ``NotImplementedError``
        without a ``__cause__`` is raised again as a new exception of the same type, its message
        wrapped by :func:`wrap_message` (``from None``); one with a cause, and any other
        exception, propagates unchanged.
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
    """The random generator of a check's visible (fixed seed) or hidden cases.

    Parameters
    ----------
    hidden : bool
        False: seeded with :data:`SEED`. True: with the integer in the environment variable
        :data:`HIDDEN_SEED_VARIABLE`, or a built-in hidden seed when it is unset or empty.

    Returns
    -------
    numpy.random.Generator
        A new generator, so every call starts the same sequence.

    Raises
    ------
    ValueError
        ``hidden`` is True and the environment variable is not a non-negative integer.
    """
    return np.random.default_rng(_hidden_seed() if hidden else SEED)


def ok(message, hidden=False):
    """Print the success line of a check (hidden cases pass silently).

    Parameters
    ----------
    message : str
        What passed; printed after a check mark, ``"\u2713 {message}"``.
    hidden : bool
        True prints nothing.
    """
    if not hidden:
        print(f"\u2713 {message}")


def fmt(x):
    """Short text for an input in a failure message.

    Parameters
    ----------
    x : object
        A function, a number, an array or anything else.

    Returns
    -------
    str
        A function's ``__name__`` (or ``"a function"``), the ``repr`` of a non-numeric value,
        the values of an array of at most 8 entries on one line (6 digits), else
        ``"an array of shape (...)"``.
    """
    if callable(x):
        return getattr(x, "__name__", "a function")
    arr = np.asarray(x)
    if arr.dtype == object:
        return repr(x)
    if arr.size <= 8:
        return np.array2string(arr, precision=6, separator=", ", suppress_small=False).replace("\n", "")
    return f"an array of shape {arr.shape}"


def _split_first_line(text):
    """``(first, rest)`` with ``first`` at most MAX_FIRST_LINE characters (wrapped at a space)."""
    first, _, rest = text.partition("\n")
    limit = _hiding.MAX_FIRST_LINE
    if len(first) > limit:
        cut = first.rfind(" ", 0, limit + 1)
        cut = cut if cut > limit // 2 else limit
        first, rest = first[:cut].rstrip(), (first[cut:].strip() + ("\n" + rest if rest else ""))
    return first, rest


def wrap_message(text):
    """``text`` with its first line at most 79 characters and every later line wrapped at 79.

    The shape of every failure message (see the module docstring); a message already in that
    shape is returned unchanged.

    Parameters
    ----------
    text : str

    Returns
    -------
    str
    """
    first, rest = _split_first_line(text)
    lines = [first]
    for line in rest.split("\n") if rest else ():
        short = len(line) <= _hiding.MAX_FIRST_LINE
        lines.extend([line] if short else textwrap.wrap(line, _hiding.MAX_FIRST_LINE, break_on_hyphens=False))
    return "\n".join(lines)


def fail(name, hint, *details):
    """An ``AssertionError``: ``"{name}: {first line of hint}"``, then the details.

    Parameters
    ----------
    name : str
        The student's function ("" if ``hint`` names it already).
    hint : str
        First line: the mistake in a few words; later lines: the explanation.
    details : str
        Further lines (the input, expected and actual values...); empty ones are skipped.

    Returns
    -------
    AssertionError
        To be raised by the caller.
    """
    first, rest = _split_first_line(f"{name}: {hint}" if name else hint)
    lines = [first]
    for text in (rest, *details):
        for line in text.split("\n") if text else ():
            short = len(line) <= _hiding.MAX_FIRST_LINE
            lines.extend([line] if short else textwrap.wrap(line, _hiding.MAX_FIRST_LINE, break_on_hyphens=False))
    return AssertionError("\n".join(lines))


def _materialize(out, name):
    """The student's output as plain float arrays (tuples stay tuples), computed now.

    Converting inside the guarded call means a lazy object cannot call the library later.
    """
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
    """``arr`` as float64, or a failure if it is complex (not rounding noise) or single precision.

    ``np.array(out, dtype=float)`` alone would drop imaginary parts (with a warning only) and
    would hide that a float32 result kept 7 digits, which the checks then blame on the math.
    """
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
    """Name of the function that raised ``err``, if it is not ``fn`` itself (else None).

    A student's answer that calls another of their functions still a stub (``pose_jacobian``
    calling their unfinished ``odot``) is not itself unfinished: the message must name the stub.
    """
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
    """``value`` with every array (also inside tuples, lists and dicts) copied.

    The student's function gets its own copies: code that updates its inputs in place
    (``m += K @ r``) is then judged by its result, and the check's reference, computed from the
    same inputs afterwards, is not changed under it.
    """
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

    Returns
    -------
    callable
        Same arguments as ``fn``; returns its output as float arrays; raises
        ``NotImplementedError`` for a stub and ``AssertionError`` (a short first line) for a
        crash, a call to a hidden function or a change to visla_edu.
    """
    return _Student(fn, name, hide)


def as_array(out, name, shape, what="result"):
    """The student's output as a float array of the expected shape, or a failure with a hint.

    Parameters
    ----------
    out : array_like
        The student's output.
    name : str
        The student's function, first word of a failure.
    shape : tuple of int
        The expected shape.
    what : str
        What ``out`` is, for the message (e.g. ``"pose"``, ``"covariance"``).

    Returns
    -------
    ndarray, shape ``shape``
        ``out`` as float.

    Raises
    ------
    AssertionError
        ``out`` is not numeric, or has another shape (the hint says when it is the transpose,
        or has the right number of entries).
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
    """True if ``a`` and ``b`` have one shape and agree (NaN equal to NaN).

    Agreement is ``numpy.allclose``: ``|a - b| <= atol + rtol |b|`` entry by entry.

    Parameters
    ----------
    a, b : array_like
        Converted to float arrays.
    rtol, atol : float
        Relative and absolute tolerance.

    Returns
    -------
    bool
        False when the shapes differ (no broadcasting).

    Raises
    ------
    TypeError, ValueError
        ``a`` or ``b`` cannot be converted to a float array.
    """
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
    """The hint of the deliberate mistake whose output equals ``got`` (or None).

    Where several mistakes nearly coincide (at a tiny angle ``R^T``, ``V^T v`` and ``v`` are all
    within the matching tolerance of one another and of the right answer), the first match is
    not the mistake: the variant closest to ``got`` wins (the first of equally close ones), and
    only if ``got`` is closer to it than to ``expected``.
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
    """Fail with the most specific message if ``got`` differs from ``expected``.

    The checks, in order: ``got`` agrees with ``expected`` (:func:`close`: same shape,
    ``|got - expected| <= atol + rtol |expected|``, NaN equal to NaN), then NaN or inf where
    ``expected`` is finite, then the variants, then ``extra``; else the message shows both
    arrays.

    Parameters
    ----------
    name : str
        The student's function, first word of the message.
    got : array_like
        The student's output (numeric).
    expected : array_like
        The reference output.
    where : str
        The input, e.g. ``"for w = [1, 2, 3]"`` (second line of the message).
    variants : sequence of (hint, callable)
        Each callable returns the output of one deliberate mistake on the same input; a
        variant that matches ``got`` names the mistake (of several, the closest to ``got``,
        and only if ``got`` is closer to it than to ``expected``). A hint's first line is
        short. A variant that raises is skipped; the match uses at least ``rtol = 1e-6`` and
        ``atol = 1e-8``.
    rtol : float
        Relative tolerance of the agreement.
    atol : float
        Absolute tolerance of the agreement.
    nan_hint : str
        Hint when ``got`` has NaN or inf and ``expected`` has not.
    extra : callable, optional
        ``extra(got)`` returns a hint (or "") for mistakes found by a property of the
        output (e.g. "not a rotation").

    Raises
    ------
    AssertionError
        ``got`` differs from ``expected``; nothing happens when they agree.
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
    """The student's function if it runs on ``probe_args`` and agrees with the reference.

    Later cells of a notebook use this so that an unfinished exercise never blocks them.
    It prints which function it uses: ``"using your {name}"``, or ``"using the library's
    {name} (yours is not finished or disagrees)"``.

    Parameters
    ----------
    student_fn : callable
        The student's function.
    reference_fn : callable
        The library's version, same arguments and outputs.
    *probe_args
        One input for both; the outputs (arrays, or tuples and lists of them) must agree to
        ``rtol = 1e-5``, ``atol = 1e-7``. Any exception (e.g. ``NotImplementedError`` of a
        stub) counts as disagreement.
    name : str, optional
        Shown in the printed line; default ``student_fn.__name__``.

    Returns
    -------
    callable
        ``student_fn`` if it agrees, else ``reference_fn``.
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
