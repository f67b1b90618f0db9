"""The package's shape, as the maintainers' rules state it (README, "For maintainers").

No import cycle between the package's modules, imports that follow the README's layers (each
module listed in one, importing nothing of a later one), no module over 600 lines, no function
over 60 lines of code, and the slow scipy.stats import kept out of the drivers' import path.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "visla_edu"
MAX_MODULE_LINES = 600
MAX_FUNCTION_CODE_LINES = 60


def _module_name(path):
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules():
    return {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _from_base(node, here, modules):
    """The absolute module name of a ``from ... import`` statement in module ``here`` (relative ones resolved)."""
    base = node.module or ""
    if node.level:
        package = here if modules[here].name == "__init__.py" else here.rpartition(".")[0]
        for _ in range(node.level - 1):
            package = package.rpartition(".")[0]
        base = f"{package}.{base}" if base else package
    return base


def _targets(node, here, modules):
    """Package modules a top-level import statement loads (a submodule, not its package, when named)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names if alias.name in modules]
    base = _from_base(node, here, modules)
    found = [f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in modules]
    return found or ([base] if base in modules else [])


def import_graph():
    """``{module: set of package modules it imports at module level}``."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        edges = set()
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                edges.update(_targets(node, name, modules))
        graph[name] = edges - {name}
    return graph


def find_cycle(graph):
    """One import cycle as a list of module names, or ``None``."""
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_graph_sees_the_package_imports():
    graph = import_graph()
    assert "visla_edu.lie" in graph["visla_edu.motion"]
    assert "visla_edu.smoother._normal" in graph["visla_edu.smoother._batch"]


def test_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def readme_layers():
    """``{module: layer number}`` of the README's "For maintainers" list, packages as ``visla_edu.data``.

    Each numbered item (``1. **Math** ...``) names its modules in backticks: ``lie``,
    ``smoother/_se3``, ``data/``; backticked words that are not modules of the package (a
    package's submodules in parentheses, functions) are skipped.
    """
    import re

    text = (PACKAGE.parent / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## For maintainers"):]
    modules = _modules()
    layers = {}
    for number, body in re.findall(r"^(\d)\. \*\*.*?\*\*(.*?)(?=^\d\. \*\*|^$)", section, flags=re.M | re.S):
        for token in re.findall(r"`([\w/]+)`", body):
            name = "visla_edu." + token.strip("/").replace("/", ".")
            if name in modules:
                layers.setdefault(name, int(number))
    return layers


def _layer(module, layers):
    """The layer of ``module``: that of the longest listed name it is or lies under (None if unlisted)."""
    owners = [name for name in layers if module == name or module.startswith(name + ".")]
    return layers[max(owners, key=len)] if owners else None


def test_every_module_is_in_a_readme_layer():
    layers = readme_layers()
    unlisted = [name for name in _modules() if name.count(".") == 1 and not name.endswith("__main__")
                and _layer(name, layers) is None]
    assert not unlisted, f"modules missing from the README's layers (For maintainers): {unlisted}"


def test_imports_go_downwards_only():
    """The README's rule: a module imports only modules of its own layer or of the layers above it in the list."""
    layers = readme_layers()
    upward = [f"{module} (layer {_layer(module, layers)}) imports {target} (layer {_layer(target, layers)})"
              for module, targets in sorted(import_graph().items()) for target in sorted(targets)
              if None not in (_layer(module, layers), _layer(target, layers))
              and _layer(target, layers) > _layer(module, layers)]
    assert not upward, "imports against the README's layers: " + "; ".join(upward)


@pytest.mark.parametrize("name, path", sorted(_modules().items()))
def test_module_is_at_most_600_lines(name, path):
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_MODULE_LINES, f"{name} has {lines} lines; split it by concept"


def _code_lines(function, source_lines):
    body = function.body
    first = body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        start = first.end_lineno
    else:
        start = first.lineno - 1
    lines = source_lines[start:function.end_lineno]
    return sum(1 for line in lines if line.strip() and not line.strip().startswith("#"))


def test_no_function_over_60_lines_of_code():
    long = []
    for name, path in _modules().items():
        source = path.read_text()
        lines = source.splitlines()
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                count = _code_lines(node, lines)
                if count > MAX_FUNCTION_CODE_LINES:
                    long.append(f"{name}.{node.name} ({count})")
    assert not long, "functions over 60 lines of code: " + ", ".join(long)


def test_a_filter_run_does_not_import_scipy_stats():
    code = ("import sys, visla_edu.run, visla_edu.diagnostics, visla_edu.smoother, visla_edu.cli; "
            "from visla_edu import data, run; from visla_edu.filters import FilterConfig; "
            "run.run_filter(data.load('sim-tiny'), 'slam', FilterConfig(), progress=False); "
            "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", "scipy.stats was imported by a filter run; use metrics.chi2_quantile (scipy.special)"


def _private_owner(dotted):
    """The package that owns the first private part of ``dotted`` (``visla_edu.data`` for
    ``visla_edu.data._groundtruth.MIN_POSES``), or ``None`` when no part is private."""
    parts = dotted.split(".")
    for index, part in enumerate(parts):
        if part.startswith("_") and not part.startswith("__"):
            return ".".join(parts[:index])
    return None


def _imported_names(node, here, modules):
    """Dotted names an import statement (anywhere in a module) reaches: modules and their attributes."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = _from_base(node, here, modules)
    return [base] + [f"{base}.{alias.name}" for alias in node.names]


def private_imports_across_packages():
    """``module -> name`` strings: imports of a private module or name from outside the package that owns it."""
    modules = _modules()
    found = []
    for here, path in modules.items():
        package = here if path.name == "__init__.py" else here.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for name in _imported_names(node, here, modules):
                owner = _private_owner(name) if name.startswith("visla_edu") else None
                if owner is not None and not (package == owner or package.startswith(owner + ".")):
                    found.append(f"{here} -> {name}")
    return sorted(set(found))


def test_private_import_finder_sees_one():
    assert _private_owner("visla_edu.data._groundtruth.MIN_POSES") == "visla_edu.data"
    assert _private_owner("visla_edu.filters.FilterBase") is None
    assert _private_owner("visla_edu._files") == "visla_edu"


def test_no_private_module_is_imported_from_another_package():
    found = private_imports_across_packages()
    assert not found, "private names imported from outside their package: " + "; ".join(found)


MAX_TOP_LEVEL_MODULES = 14


def test_at_most_14_plain_modules_at_the_top():
    """Course scaffolding, drivers and the command line live in their subpackages, so the top of
    ``visla_edu/`` shows the library's concepts (``__init__`` and ``__main__`` not counted)."""
    plain = sorted(path.stem for path in PACKAGE.glob("*.py") if path.stem not in ("__init__", "__main__"))
    assert len(plain) <= MAX_TOP_LEVEL_MODULES, f"{len(plain)} plain modules at the top of visla_edu/: {plain}"


def _is_state_sigma(node, views_only=False):
    """``node`` is ``<x>.state.Sigma`` or a subscript of it (with ``views_only``: a basic slice,
    which shares memory; an index array or ``np.ix_`` makes a copy)."""
    while isinstance(node, ast.Subscript):
        index = node.slice.elts if isinstance(node.slice, ast.Tuple) else [node.slice]
        if views_only and not all(isinstance(i, (ast.Slice, ast.Constant)) for i in index):
            return False
        node = node.value
    return (isinstance(node, ast.Attribute) and node.attr == "Sigma" and isinstance(node.value, ast.Attribute)
            and node.value.attr == "state")


def _covariance_writes(tree):
    """Lines where ``<x>.state.Sigma`` is assigned into, or handed to a call (which may change it in
    place) whole or as a view."""
    lines = []
    for node in ast.walk(tree):
        targets = (node.targets if isinstance(node, ast.Assign) else [node.target]
                   if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else [])
        args = [*node.args, *(k.value for k in node.keywords)] if isinstance(node, ast.Call) else []
        lines += [node.lineno for target in targets if _is_state_sigma(target)]
        lines += [node.lineno for arg in args if _is_state_sigma(arg, views_only=True)]
    return lines


def test_the_covariance_finder_sees_writes():
    tree = ast.parse("self.state.Sigma[0] = 1\nf(self.state.Sigma)\nx = self.state.Sigma[:, 0] @ H\n"
                     "g(self.state.Sigma[:6])\nh(self.state.Sigma[np.ix_(U, U)])\nself.state.Sigma -= A\n")
    assert sorted(_covariance_writes(tree)) == [1, 2, 4, 6]


def test_only_the_state_helper_changes_the_joint_covariance():
    """``filters._state.ActiveSet`` owns the covariance: the filters read ``state.Sigma`` and change
    it only through the helper's methods (propagate, update, correct, augment, retire...)."""
    found = [f"{name}:{line}" for name, path in _modules().items() if name != "visla_edu.filters._state"
             for line in _covariance_writes(ast.parse(path.read_text(), filename=str(path)))]
    assert not found, "the joint covariance changed outside ActiveSet: " + ", ".join(found)


@pytest.mark.parametrize("name", ["checks", "odometry", "workload"])
def test_a_moved_module_says_where_it_is_now(name):
    """A notebook from an earlier version (``from visla_edu import checks``) gets one line naming the new import."""
    import importlib

    import visla_edu

    with pytest.raises(ImportError, match=rf"visla_edu\.{name} moved to {visla_edu.MOVED[name]}\.{name}"):
        exec(f"from visla_edu import {name}", {})  # noqa: S102
    importlib.import_module(f"{visla_edu.MOVED[name]}.{name}")  # where it is now imports
    with pytest.raises(AttributeError, match="no attribute 'no_such_module'"):
        visla_edu.no_such_module  # noqa: B018
