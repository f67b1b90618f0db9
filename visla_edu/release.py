"""Generate the student notebooks from the solution notebooks (the single source).

``solutions/*.ipynb`` hold the full course: derivations, exercises with their solutions
between nbgrader's markers, and graded check cells. This module turns them into
``notebooks/*.ipynb``, the files students open:

* in every cell, the lines between ``### BEGIN SOLUTION`` and ``### END SOLUTION`` are
  replaced by a stub (``raise NotImplementedError(...)`` in code, ``YOUR ANSWER HERE`` in
  markdown) at the indentation of the ``BEGIN`` marker, so the function signature and
  docstring above the marker stay;
* the lines between ``### BEGIN HIDDEN TESTS`` and ``### END HIDDEN TESTS`` (markers
  included) are removed, so only the teacher's copy runs them;
* outputs, execution counts and per-run metadata (``execution``, ``collapsed``...) are
  removed; notebook and nbgrader cell metadata are kept, so nbgrader can grade the result.

The output depends only on the input (no time stamps, no random cell ids), so the student
notebooks can be checked in and a test can prove they are in sync::

    python -m visla_edu.release                 # solutions/ -> notebooks/
    python -m visla_edu.release --check         # exit 1 and list the drifted files
    python -m visla_edu.release --clean-sources # also strip outputs from solutions/

Nothing here shells out to nbgrader; only :mod:`nbformat` is used.
"""

import argparse
import copy
import re
import sys
from pathlib import Path

from visla_edu._files import atomic_write

__all__ = [
    "BEGIN_SOLUTION",
    "END_SOLUTION",
    "BEGIN_HIDDEN",
    "END_HIDDEN",
    "stub_source",
    "strip_hidden_tests",
    "clean_notebook",
    "student_notebook",
    "notebook_text",
    "make_student_notebooks",
    "check_in_sync",
    "clean_sources",
    "main",
]

BEGIN_SOLUTION = "### BEGIN SOLUTION"
END_SOLUTION = "### END SOLUTION"
BEGIN_HIDDEN = "### BEGIN HIDDEN TESTS"
END_HIDDEN = "### END HIDDEN TESTS"

#: Cell metadata keys that describe one execution, not the notebook.
_RUN_METADATA = ("execution", "collapsed", "scrolled", "ExecuteTime")

_CODE_STUB = 'raise NotImplementedError("{what}: write your solution here")'
_MARKDOWN_STUB = "YOUR ANSWER HERE"

_DEFAULT_SRC = "solutions"
_DEFAULT_DST = "notebooks"


def _nbformat():
    import nbformat  # lazy: the library itself does not need it

    return nbformat


def _marker_regions(lines, begin, end, where):
    """Yield ``(start, stop)`` line indices of each ``begin``..``end`` region (markers included)."""
    start = None
    for i, line in enumerate(lines):
        text = line.strip()
        if text == begin:
            if start is not None:
                raise ValueError(f"{where}: {begin!r} on line {i + 1} inside an open region (line {start + 1})")
            start = i
        elif text == end:
            if start is None:
                raise ValueError(f"{where}: {end!r} on line {i + 1} without a matching {begin!r}")
            yield start, i
            start = None
    if start is not None:
        raise ValueError(f"{where}: {begin!r} on line {start + 1} is never closed by {end!r}")


def stub_source(source, cell_type="code", what="exercise", where="cell"):
    """Replace every solution region of ``source`` by a stub.

    Parameters
    ----------
    source : str
        Cell source.
    cell_type : {"code", "markdown"}
    what : str
        Named in the stub's message (e.g. the exercise's grade id).
    where : str
        Named in error messages about unbalanced markers.

    Returns
    -------
    str
    """
    lines = source.split("\n")
    regions = list(_marker_regions(lines, BEGIN_SOLUTION, END_SOLUTION, where))
    if not regions:
        return source
    out, prev = [], 0
    for start, stop in regions:
        out.extend(lines[prev:start])
        indent = re.match(r"\s*", lines[start]).group(0)
        if cell_type == "code":
            out.append(indent + _CODE_STUB.format(what=what))
        else:
            out.append(indent + _MARKDOWN_STUB)
        prev = stop + 1
    out.extend(lines[prev:])
    return "\n".join(out)


def strip_hidden_tests(source, where="cell"):
    """Remove every hidden-test region of ``source`` (markers included)."""
    lines = source.split("\n")
    regions = list(_marker_regions(lines, BEGIN_HIDDEN, END_HIDDEN, where))
    if not regions:
        return source
    out, prev = [], 0
    for start, stop in regions:
        out.extend(lines[prev:start])
        prev = stop + 1
    out.extend(lines[prev:])
    while out and not out[-1].strip():  # no trailing blank lines where the tests were
        out.pop()
    return "\n".join(out)


def clean_notebook(nb):
    """A copy of ``nb`` without outputs, execution counts and per-run cell metadata."""
    nb = copy.deepcopy(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = []
            cell.execution_count = None
        for key in _RUN_METADATA:
            cell.metadata.pop(key, None)
        # attachments of markdown cells are content and stay
    return nb


def _is_solution_cell(cell):
    return bool(cell.metadata.get("nbgrader", {}).get("solution", False))


def student_notebook(nb, name="notebook"):
    """The student version of a solution notebook (a new object).

    Parameters
    ----------
    nb : nbformat.NotebookNode
    name : str
        Used in error messages (unbalanced markers) and nothing else.

    Returns
    -------
    nbformat.NotebookNode
    """
    nb = clean_notebook(nb)
    for index, cell in enumerate(nb.cells):
        where = f"{name} cell {index}"
        source = cell.source
        if BEGIN_SOLUTION in source:
            what = cell.metadata.get("nbgrader", {}).get("grade_id", f"cell {index}")
            source = stub_source(source, cell.cell_type, what=what, where=where)
        elif _is_solution_cell(cell) and cell.cell_type == "markdown":
            source = _MARKDOWN_STUB
        if BEGIN_HIDDEN in source:
            source = strip_hidden_tests(source, where=where)
        cell.source = source
    return nb


def notebook_text(nb):
    """The exact text a notebook is stored as (nbformat's JSON, newline at the end)."""
    nbformat = _nbformat()
    text = nbformat.writes(nb, version=4)
    return text if text.endswith("\n") else text + "\n"


def _read(path):
    return _nbformat().read(str(path), as_version=4)


def _sources(src_dir):
    src_dir = Path(src_dir)
    if not src_dir.is_dir():
        raise FileNotFoundError(f"solution notebooks folder {src_dir} does not exist")
    paths = sorted(p for p in src_dir.glob("*.ipynb") if not p.name.startswith("."))
    if not paths:
        raise FileNotFoundError(f"no .ipynb files in {src_dir}")
    return paths


def _expected(src_dir):
    """File name -> expected student notebook text, for every solution notebook."""
    return {p.name: notebook_text(student_notebook(_read(p), p.name)) for p in _sources(src_dir)}


def make_student_notebooks(src_dir=_DEFAULT_SRC, dst_dir=_DEFAULT_DST):
    """Write the student version of every ``src_dir/*.ipynb`` to ``dst_dir``.

    Files are rewritten only when their content changes, each atomically (an interrupted
    release leaves every notebook whole, old or new). Student notebooks without a solution
    notebook are left alone (:func:`check_in_sync` reports them).

    Parameters
    ----------
    src_dir, dst_dir : str or os.PathLike

    Returns
    -------
    list of pathlib.Path
        The files written (changed or new).
    """
    dst_dir = Path(dst_dir)
    dst_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in _expected(src_dir).items():
        target = dst_dir / name
        if target.is_file() and target.read_text(encoding="utf-8") == text:
            continue
        _write_text(target, text)
        written.append(target)
    return written


def _write_text(path, text):
    """Write a notebook atomically (:func:`visla_edu._files.atomic_write`): never half a notebook."""
    with atomic_write(path, "w", encoding="utf-8") as f:
        f.write(text)


def check_in_sync(src_dir=_DEFAULT_SRC, dst_dir=_DEFAULT_DST):
    """Student notebooks that differ from what :func:`make_student_notebooks` would write.

    Parameters
    ----------
    src_dir, dst_dir : str or os.PathLike

    Returns
    -------
    list of str
        File names: missing or different in ``dst_dir``, or present in ``dst_dir`` without a
        solution notebook. Empty when everything is in sync.
    """
    dst_dir = Path(dst_dir)
    expected = _expected(src_dir)
    drifted = []
    for name, text in expected.items():
        target = dst_dir / name
        if not target.is_file() or target.read_text(encoding="utf-8") != text:
            drifted.append(name)
    if dst_dir.is_dir():
        drifted.extend(sorted(p.name for p in dst_dir.glob("*.ipynb") if p.name not in expected))
    return drifted


def clean_sources(src_dir=_DEFAULT_SRC):
    """Strip outputs and execution counts from the solution notebooks themselves.

    Returns
    -------
    list of pathlib.Path
        The files rewritten.
    """
    written = []
    for path in _sources(src_dir):
        text = notebook_text(clean_notebook(_read(path)))
        if path.read_text(encoding="utf-8") != text:
            _write_text(path, text)
            written.append(path)
    return written


def main(argv=None):
    """Command line: ``python -m visla_edu.release [--src DIR] [--dst DIR] [--check] [--clean-sources]``."""
    parser = argparse.ArgumentParser(
        prog="python -m visla_edu.release",
        description="Generate the student notebooks (stubs, no hidden tests, no outputs) from the solutions.",
    )
    parser.add_argument("--src", default=_DEFAULT_SRC, help="solution notebooks folder (default: solutions)")
    parser.add_argument("--dst", default=_DEFAULT_DST, help="student notebooks folder (default: notebooks)")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the student notebooks are out of date")
    parser.add_argument("--clean-sources", action="store_true",
                        help="first strip outputs and execution counts from the solution notebooks")
    args = parser.parse_args(argv)
    try:
        if args.check:
            drifted = check_in_sync(args.src, args.dst)
            if drifted:
                print(f"out of date in {args.dst}: {', '.join(drifted)}\n"
                      f"run: python -m visla_edu.release --src {args.src} --dst {args.dst}")
                return 1
            print(f"{args.dst} is in sync with {args.src}")
            return 0
        if args.clean_sources:
            for path in clean_sources(args.src):
                print(f"cleaned {path}")
        written = make_student_notebooks(args.src, args.dst)
    except (FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for path in written:
        print(f"wrote {path}")
    print(f"{len(written)} student notebook(s) updated in {args.dst}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
