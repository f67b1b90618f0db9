"""What a graded submission may use of visla_edu, and how the rest is hidden from it.

Usable: :data:`ALLOWED_MODULES`, :data:`ALLOWED_PACKAGES`, :data:`ALLOWED_NAMES`, :data:`FILTERS_INTERFACE`
(PROJECT.md, "What you may use"). The rest is hidden in three layers, the first two only in the grading
process (:mod:`visla_edu.course._grader_child`, which exits afterwards, so nothing is put back):

1. :func:`hide_library` swaps every function's code for a stub that records the call in :data:`HIDDEN_CALLS`
   and raises :class:`SubmissionUsedLibrary`, so every alias fails alike (as ``checks._hiding.hide``);
2. :func:`block_imports` refuses to load or reload a hidden module (a reload would restore its code);
3. :func:`scan_source` marks for a human what could go around layers 1 and 2; it refuses nothing.

Code in the same process can still defeat this (TEACHING.md, "Running students' code safely").
"""

import ast
import sys
import types

from visla_edu.course.checks import LibraryFunctionHidden, function_label

__all__ = ["ALLOWED_MODULES", "ALLOWED_PACKAGES", "ALLOWED_NAMES", "HIDDEN_CALLS", "SubmissionUsedLibrary", "is_hidden", "hide_library",
           "block_imports", "scan_source"]

#: visla_edu modules a submission may use while it is graded.
ALLOWED_MODULES = ("visla_edu", "visla_edu.lie", "visla_edu.camera", "visla_edu.dataset", "visla_edu.codes",
                   "visla_edu.metrics", "visla_edu.course.numdiff", "visla_edu.course.kalman", "visla_edu.filters",
                   "visla_edu.filters._config", "visla_edu.settings", "visla_edu.validation")
#: Packages whose every submodule a submission may use (the camera model is a package).
ALLOWED_PACKAGES = ("visla_edu.camera",)
#: Names a submission may use from otherwise hidden modules (the interface's types).
ALLOWED_NAMES = {"visla_edu.filters._base": ("StepRecord", "FilterDivergedError", "MIN_DEPTH", "MAX_DISTANCE")}
#: The names of the ``visla_edu.filters`` package a submission may import (the rest are its filters).
FILTERS_INTERFACE = ("FilterConfig", "StepRecord", "FilterDivergedError", "AUTO", "AUTO_FIELDS", "MAX_IMU_LAG",
                     "MIN_DEPTH", "MAX_DISTANCE", "OBS_USED", "OBS_GATED", "OBS_NEW", "OBS_NO_DEPTH", "OBS_FAR",
                     "OBS_IGNORED", "STATUS_NAMES")
#: The grader's own modules: never hidden (they run the submission).
GRADER_MODULES = ("visla_edu.course", "visla_edu.course._sandbox")
#: Methods hidden besides the ordinary ones (other dunders, such as ``__repr__``, keep working).
_HIDDEN_DUNDERS = ("__init__", "__new__", "__post_init__", "__call__", "__iter__", "__next__", "__getitem__")

#: Hidden functions the submission called (labels, in order), caught or not.
HIDDEN_CALLS = []


class SubmissionUsedLibrary(LibraryFunctionHidden):
    """Raised by a hidden function; ``hidden`` is its label (:func:`visla_edu.course.checks.function_label`)."""

    def __init__(self, hidden):
        super().__init__(f"{hidden} is hidden while a submission is graded: the project asks for your own filter "
                         "(PROJECT.md, 'What you may use')")
        self.hidden = hidden


def refuse(name):
    """Record a call of the hidden function ``name`` and return the error its stub raises."""
    HIDDEN_CALLS.append(name)
    return SubmissionUsedLibrary(name)


def is_hidden(module_name):
    """True for a visla_edu module (dotted name) a submission may not use (the module docstring)."""
    inside = module_name == "visla_edu" or module_name.startswith("visla_edu.")
    in_package = any(module_name.startswith(package + ".") for package in ALLOWED_PACKAGES)
    return inside and not in_package and module_name not in ALLOWED_MODULES + GRADER_MODULES


def _stub_code(fn, name):
    """A code object for ``fn`` (same name, same free variables) that raises :func:`refuse`'s error."""
    free = fn.__code__.co_freevars
    lines = ["def _outer():", *(f"    {var} = None" for var in free), "    def _hidden(*args, **kwargs):"]
    if free:
        lines.append(f"        ({', '.join(free)},)")  # makes them free variables of the stub
    lines += [f"        raise __import__('sys').modules[{__name__!r}].refuse({name!r})", "    return _hidden"]
    namespace = {}
    exec(compile("\n".join(lines), f"<hidden by visla_edu's grader: {name}>", "exec"), namespace)  # noqa: S102
    return namespace["_outer"]().__code__.replace(co_name=fn.__code__.co_name)


def _functions_of(module):
    """``(label, function)`` of the functions and methods defined in ``module``, except the allowed names."""
    allowed = ALLOWED_NAMES.get(module.__name__, ())
    for attr, value in list(vars(module).items()):
        if attr in allowed or getattr(value, "__module__", None) != module.__name__:
            continue
        value = getattr(value, "__wrapped__", value)  # functools.lru_cache and friends call the wrapped function
        if isinstance(value, types.FunctionType):
            yield function_label(value), value
        elif isinstance(value, type):
            yield from _methods_of(value)


def _methods_of(cls):
    """``(label, function)`` of a class's own methods, properties' accessors included."""
    for key, member in list(vars(cls).items()):
        if key.startswith("__") and key not in _HIDDEN_DUNDERS:
            continue
        if isinstance(member, property):
            parts = (member.fget, member.fset, member.fdel)
        else:
            parts = (getattr(member, "__func__", getattr(member, "func", member)),)
        for part in parts:
            if isinstance(part, types.FunctionType):
                yield function_label(part), part


def hide_library():
    """Make every function and method of loaded hidden modules raise :class:`SubmissionUsedLibrary`; return how many."""
    found = {}  # all of them first: the labels and stubs are made with functions that get hidden too
    for name, module in sorted(sys.modules.items()):
        if isinstance(module, types.ModuleType) and is_hidden(name):
            found.update((id(fn), (fn, _stub_code(fn, fn_label))) for fn_label, fn in _functions_of(module))
    for fn, stub in found.values():
        fn.__code__ = stub
    return len(found)


class _HiddenImports:
    """A ``sys.meta_path`` finder that refuses hidden visla_edu modules (new imports and reloads)."""

    @staticmethod
    def find_spec(fullname, path=None, target=None):
        if is_hidden(fullname):
            HIDDEN_CALLS.append(f"import {fullname}")
            raise ImportError(f"{fullname} is hidden while a submission is graded: the project asks for your own "
                              "filter (PROJECT.md, 'What you may use')", name=fullname)
        return None


def block_imports():
    """Refuse, from now on, to import a hidden visla_edu module that is not loaded, or to reload one."""
    sys.meta_path.insert(0, _HiddenImports())


# ----------------------------------------------------------------------------- the static marks

#: Modules whose import is marked: they run other programs, reach into the interpreter or the network.
MARKED_MODULES = ("importlib", "subprocess", "multiprocessing", "ctypes", "inspect", "builtins", "gc", "socket",
                  "urllib", "http", "requests", "pty", "marshal", "pickle", "runpy", "code")
#: Calls that are marked, with what they can do.
MARKED_CALLS = {
    "exec": "runs code built at run time", "eval": "runs code built at run time",
    "compile": "builds code at run time", "__import__": "imports by name at run time",
    "system": "runs another program", "popen": "runs another program", "open": "reads or writes a file",
    "load": "reads a file", "loadtxt": "reads a file", "genfromtxt": "reads a file", "fromfile": "reads a file",
    "read_text": "reads a file", "read_bytes": "reads a file", "glob": "lists a folder", "listdir": "lists a folder",
    "scandir": "lists a folder", "walk": "lists a folder", "iterdir": "lists a folder",
    "getenv": "reads the environment",
}
#: Attributes that are marked: they reach into the interpreter.
MARKED_ATTRIBUTES = {"modules": "reaches into sys.modules", "__code__": "reads or replaces a function's code",
                     "__globals__": "reaches into a function's module", "__subclasses__": "walks the class tree",
                     "meta_path": "changes how modules are imported", "environ": "reads the environment"}


def _hidden_imports(node):
    """The hidden visla_edu modules or names one import statement imports."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names if is_hidden(alias.name)]
    base = node.module or ""
    names = [alias.name for alias in node.names]
    if base == "visla_edu.filters":
        return [f"{base}.{name}" for name in names if name not in FILTERS_INTERFACE]
    if base in ALLOWED_NAMES:
        return [f"{base}.{name}" for name in names if name not in ALLOWED_NAMES[base]]
    if base == "visla_edu":
        return [f"{base}.{name}" for name in names if is_hidden(f"{base}.{name}")]
    return [f"{base}.{name}" for name in names] if is_hidden(base) else []


def _marks_of(node):
    """The marks of one syntax node (see :func:`scan_source`)."""
    if isinstance(node, (ast.Import, ast.ImportFrom)):
        modules = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
        return ([f"imports {name}, which is hidden while it is graded" for name in _hidden_imports(node)]
                + [f"imports {name}" for name in modules if name.split(".")[0] in MARKED_MODULES])
    if isinstance(node, ast.Call):
        func = node.func
        word = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
        return [f"calls {word} ({MARKED_CALLS[word]})"] if word in MARKED_CALLS else []
    if isinstance(node, ast.Attribute) and node.attr in MARKED_ATTRIBUTES:
        return [f"uses {node.attr} ({MARKED_ATTRIBUTES[node.attr]})"]
    return []


def scan_source(source):
    """What a human should look at in a submission's Python text: ``"line N: ..."`` marks, in line order.

    Imports of hidden visla_edu modules or names and of :data:`MARKED_MODULES`, calls of :data:`MARKED_CALLS`,
    uses of :data:`MARKED_ATTRIBUTES`; ``[]`` for a text that does not parse.
    """
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return []
    found = {(node.lineno, mark) for node in ast.walk(tree) for mark in _marks_of(node)}
    return [f"line {line}: {mark}" for line, mark in sorted(found)]
