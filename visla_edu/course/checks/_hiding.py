"""What a check guards while it runs the student's code: hidden library functions, intact state.

* **Hidden** functions (the library's version of the exercise and those that would make it
  trivial) get a stub ``__code__`` raising :class:`LibraryFunctionHidden`, so every alias fails
  alike (``lie.hat``, a ``from visla_edu.lie import hat`` binding, every library caller) until a
  ``finally`` puts it back.
* Before and after each call every function of a loaded ``visla_edu`` module must come from the
  package's files (not a notebook cell), and a module attribute the call reassigned is put back
  and reported; so too for numpy, numpy.linalg and the builtins the verdicts use (an
  ``np.allclose = lambda *a, **k: True`` would pass every wrong answer).

The checks compute every expected value after the call, with nothing hidden.
"""

import builtins
import functools
import os
import sys
import types
from contextlib import contextmanager

import numpy
import numpy.linalg

__all__ = ["LibraryFunctionHidden", "function_label", "hidden_message", "hide", "guard", "verify_library",
           "verify_foundations"]

#: The ``visla_edu`` package folder: library code must come from files under it.
PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__))))

#: The builtins the checks' verdicts use (``bool(np.allclose(...))``, ``float(error) <= tol``...).
TRUSTED_BUILTINS = ("abs", "all", "any", "bool", "float", "int", "isinstance", "len", "list", "max", "min",
                    "range", "tuple", "zip")

#: Longest line of a failure message (``nbgrader validate`` cuts lines at 87 characters).
MAX_FIRST_LINE = 79


class LibraryFunctionHidden(RuntimeError):
    """Raised by a library function that a check hides (:func:`hide`); its text is :func:`hidden_message`'s."""


def function_label(fn):
    """Short dotted name of a function: ``lie.hat``, ``camera.StereoCamera.predict``, ``scipy.linalg.expm``.

    The module path without ``visla_edu``, ``course`` (``numdiff.central_jacobian``, as a notebook
    imports it) and private module names, then ``fn.__qualname__``; other packages keep their name.
    """
    package, *rest = fn.__module__.split(".")
    if package == "visla_edu" and rest[:1] == ["course"]:
        rest = rest[1:]
    parts = ([] if package == "visla_edu" else [package]) + [p for p in rest if not p.startswith("_")]
    return ".".join(parts + [fn.__qualname__])


def hidden_message(exercise, fn):
    """The error text of hiding ``fn`` from ``exercise`` (the student's function): a short line, then why.

    First line: the most explicit of four phrasings within :data:`MAX_FIRST_LINE`, else "write your own
    {exercise}" (never cut).
    """
    name = function_label(fn)
    first = next((line for line in (
        f"write your own {exercise}; the library's {name} is not available inside this check",
        f"write your own {exercise}: {name} is hidden inside this check",
        f"write your own {exercise}: {name} is hidden here",
        f"write your own {exercise}: the library's version is hidden here",
    ) if len(line) <= MAX_FIRST_LINE), f"write your own {exercise}")
    return (f"{first}\nThe check hides {name} while it runs your {exercise}, so that it "
            "grades your code, not the library's. Use numpy/scipy and the functions the exercise "
            "text allows.")


def _stub_code(fn, message):
    """A code object with ``fn``'s name whose body raises :class:`LibraryFunctionHidden`."""
    source = (f"def {fn.__name__}(*args, **kwargs):\n"
              f"    raise __import__('sys').modules[{__name__!r}].LibraryFunctionHidden({message!r})\n")
    namespace = {}
    exec(compile(source, f"<hidden by visla_edu.course.checks: {function_label(fn)}>", "exec"), namespace)  # noqa: S102
    return namespace[fn.__name__].__code__


@contextmanager
def hide(functions, exercise):
    """Within the block, calling any of ``functions`` raises :class:`LibraryFunctionHidden`.

    ``functions``: plain Python functions without closures (module functions or methods); ``exercise``
    (the student's function) is named in the error message.
    """
    saved = []
    try:
        for fn in dict.fromkeys(functions):  # each once, in order
            saved.append((fn, fn.__code__, fn.__defaults__, fn.__kwdefaults__))
            fn.__code__ = _stub_code(fn, hidden_message(exercise, fn))
            fn.__defaults__, fn.__kwdefaults__ = None, None
        yield
    finally:
        for fn, code, defaults, kwdefaults in reversed(saved):
            fn.__code__, fn.__defaults__, fn.__kwdefaults__ = code, defaults, kwdefaults


def _visla_modules():
    """``(name, module)`` of every loaded ``visla_edu`` module."""
    return [(name, module) for name, module in list(sys.modules.items())
            if (name == "visla_edu" or name.startswith("visla_edu.")) and isinstance(module, types.ModuleType)]


def _functions_of(module):
    """``(short name, function)`` of the functions and methods in ``module``, named as :func:`function_label` does."""
    short = ".".join(part for part in module.__name__.split(".")[1:] if not part.startswith("_")) or module.__name__
    for attr, value in list(vars(module).items()):
        if isinstance(value, types.FunctionType):
            yield f"{short}.{attr}", value
        elif isinstance(value, type) and value.__module__.startswith("visla_edu"):
            for key, member in list(vars(value).items()):
                member = getattr(member, "__func__", getattr(member, "fget", member))
                if isinstance(member, types.FunctionType):
                    yield f"{short}.{value.__name__}.{key}", member


def _foreign(fn):
    """True if ``fn`` was written in a notebook, or is a library function running notebook code."""
    home = str(fn.__globals__.get("__name__", ""))
    if home in ("__main__", "__mp_main__"):
        return True  # defined in the notebook (or script) itself
    if not home.startswith("visla_edu"):
        return False  # a helper of numpy, the standard library... bound in a library module
    filename = fn.__code__.co_filename
    if filename.startswith("<"):  # generated code (dataclass methods) or an interactive cell
        return filename.startswith("<ipython-input")
    return not _in_package(filename)


@functools.lru_cache(maxsize=4096)
def _in_package(filename):
    """True if the file ``filename`` lies under :data:`PACKAGE_DIR` (cached: realpath is slow)."""
    return os.path.realpath(filename).startswith(PACKAGE_DIR + os.sep)


def verify_library(modules):
    """Fail, naming the first one, if a function of ``modules`` was replaced by notebook code."""
    for module in modules:
        for name, fn in _functions_of(module):
            if _foreign(fn):
                raise AssertionError(
                    f"visla_edu's {name} was replaced by code from this notebook\n"
                    "The checks compare your functions with the library, so the library must stay as "
                    "installed: restart the kernel and run the notebook without assigning to visla_edu.")


def _numpy_impostor(value):
    """True if ``value``, an attribute of numpy, is callable but not numpy's own."""
    return callable(value) and not str(getattr(value, "__module__", None) or "").startswith("numpy")


def _builtin_impostor(name, value):
    """True if ``builtins.<name>`` is no longer Python's own type or function of that name."""
    if isinstance(value, type):
        return value.__module__ != "builtins" or value.__name__ != name
    return not (isinstance(value, types.BuiltinFunctionType) and value.__name__ == name
                and getattr(value, "__self__", None) is builtins)


def verify_foundations():
    """Fail, naming the first one, if a numpy function or a :data:`TRUSTED_BUILTINS` entry was replaced.

    Every callable of ``numpy`` and ``numpy.linalg`` must have a ``__module__`` starting with ``numpy``,
    each trusted builtin be Python's own type or built-in function of that name.
    """
    for module in (numpy, numpy.linalg):
        for attr, value in list(vars(module).items()):
            if _numpy_impostor(value):
                raise AssertionError(
                    f"{module.__name__}.{attr} was replaced by code from this notebook\n"
                    "The checks compare numbers with numpy, so numpy must stay as installed: restart the "
                    "kernel and run the notebook without assigning to numpy.")
    for name in TRUSTED_BUILTINS:
        if _builtin_impostor(name, getattr(builtins, name, None)):
            raise AssertionError(
                f"Python's built-in {name} was replaced by code from this notebook\n"
                "The checks rely on Python's built-in functions: restart the kernel and run the notebook "
                "without assigning to builtins.")


def _foundation_snapshot():
    """``(name, module, saved namespace)`` of numpy, numpy.linalg and the trusted builtins."""
    return [("numpy", numpy, dict(vars(numpy))), ("numpy.linalg", numpy.linalg, dict(vars(numpy.linalg))),
            ("builtins", builtins, {name: getattr(builtins, name) for name in TRUSTED_BUILTINS})]


def _restore_changes(snapshot):
    """Put back what was reassigned since ``snapshot``; return the names that changed."""
    changed = []
    for name, module, saved in snapshot:
        if sys.modules.get(name) is not module:
            sys.modules[name] = module
            changed.append(name)
        namespace = vars(module)
        for key, value in saved.items():
            if not key.startswith("__") and namespace.get(key, saved) is not value:
                namespace[key] = value
                changed.append(f"{name}.{key}")
    return changed


@contextmanager
def guard(functions, exercise):
    """Verify the library, hide ``functions`` (:func:`hide`), run the block, restore and verify again.

    Before: :func:`verify_library` (the checks excepted), :func:`verify_foundations` and a copy of the
    namespaces of all loaded ``visla_edu`` modules (the checks included), numpy, numpy.linalg and the
    trusted builtins. After: what the block reassigned there (or in ``sys.modules``) is put back and
    reported by an ``AssertionError`` naming ``exercise`` (it replaces any exception of the block);
    if the block completed, :func:`verify_library` again.
    """
    modules = _visla_modules()
    library = [module for name, module in modules if not name.startswith("visla_edu.course.checks")]
    verify_library(library)
    verify_foundations()
    snapshot = [(name, module, dict(vars(module))) for name, module in modules] + _foundation_snapshot()
    try:
        with hide(functions, exercise):
            yield
    finally:
        changed = _restore_changes(snapshot)
        if changed:
            what = "visla_edu" if any(n.startswith("visla_edu") for n in changed) else changed[0].split(".")[0]
            raise AssertionError(
                f"your {exercise} changed {what} while the check ran\n"
                f"It reassigned {', '.join(changed[:5])}; the check put them back. A solution must "
                "compute its result, not modify the library, the checks, numpy or Python's builtins.")
    verify_library(library)
