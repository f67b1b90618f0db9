"""What every lesson carries (issue 11): objectives and time at the top, questions and
references at the end, figures that survive a headless run, no progress bars in saved notebooks.
"""

import ast
import re
from pathlib import Path

import nbformat
import pytest

from visla_edu.course import release

ROOT = Path(__file__).resolve().parents[1]
SOLUTIONS = ROOT / "solutions"
NAMES = sorted(p.name for p in SOLUTIONS.glob("*.ipynb"))
#: The lessons: every notebook but the reference pages (the notation page).
LESSONS = [n for n in NAMES if not release.is_reference_page(nbformat.read(str(SOLUTIONS / n), as_version=4))]
#: Library calls that draw a tqdm bar unless told not to.
PROGRESS_CALLS = {"run_filter", "run_smoother"}


def _notebook(name):
    return nbformat.read(str(SOLUTIONS / name), as_version=4)


def _markdown(nb):
    return [c.source for c in nb.cells if c.cell_type == "markdown"]


def _points(nb):
    return sum(c.metadata.get("nbgrader", {}).get("points", 0) for c in nb.cells
               if c.metadata.get("nbgrader", {}).get("grade"))


@pytest.mark.parametrize("name", NAMES)
def test_lesson_opens_with_objectives_and_time(name):
    top = "\n".join(_markdown(_notebook(name))[:2])
    assert re.search(r"(?i)learning objectives", top), f"{name}: no learning objectives at the top"
    assert re.search(r"\*\*Time[:.]\*\*", top), f"{name}: no **Time:** estimate at the top"


@pytest.mark.parametrize("name", NAMES)
def test_points_quoted_at_the_top_are_the_graded_points(name):
    nb = _notebook(name)
    quoted = re.findall(r"\((\d+) points?\)", "\n".join(_markdown(nb)[:2]))
    for number in quoted:
        assert int(number) == _points(nb), f"{name}: the top says {number} points, the graded cells give {_points(nb)}"


@pytest.mark.parametrize("name", LESSONS)
def test_lesson_ends_with_questions_answers_and_references(name):
    markdown = _markdown(_notebook(name))
    questions = [i for i, text in enumerate(markdown) if "Check your understanding" in text]
    references = [i for i, text in enumerate(markdown) if re.match(r"#+ *References", text.lstrip())]
    assert questions, f"{name}: no 'Check your understanding' questions"
    assert references, f"{name}: no References section"
    answers = [i for i, text in enumerate(markdown) if release.BEGIN_ANSWERS in text]
    assert answers and answers[0] > questions[0], f"{name}: the questions have no answers region after them"


@pytest.mark.parametrize("name", LESSONS)
def test_figures_are_inline_so_headless_runs_keep_them(name):
    first = next(c for c in _notebook(name).cells if c.cell_type == "code")
    assert first.source.lstrip().startswith("%matplotlib inline"), (
        f"{name}: the first code cell must start with %matplotlib inline (with MPLBACKEND=Agg, "
        "as in CI and nbgrader, figures are otherwise not kept)")


def _calls_without_progress_false(source):
    code = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith(("%", "!")))
    try:
        tree = ast.parse(code)
    except SyntaxError:
        return []
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if fname in PROGRESS_CALLS:
                progress = [k for k in node.keywords if k.arg == "progress"]
                if not progress or not (isinstance(progress[0].value, ast.Constant) and progress[0].value.value is False):
                    bad.append(f"{fname} (line {node.lineno})")
    return bad


def test_progress_finder_sees_a_missing_flag():
    assert _calls_without_progress_false("r = run.run_filter(ds, 'slam')") == ["run_filter (line 1)"]
    assert _calls_without_progress_false("r = run.run_filter(ds, 'slam', progress=False)") == []


@pytest.mark.parametrize("name", NAMES)
def test_no_progress_bars_in_saved_notebooks(name):
    bad = [f"cell {i}: {call}" for i, c in enumerate(_notebook(name).cells) if c.cell_type == "code"
           for call in _calls_without_progress_false(c.source)]
    assert not bad, f"{name}: pass progress=False (a tqdm widget bar is saved as '0%'): " + "; ".join(bad)


def test_headless_run_keeps_an_inline_figure(monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell("%matplotlib inline\nimport matplotlib.pyplot as plt\n"
                                          "plt.plot([0, 1], [1, 0])\nplt.show()")]
    nbclient.NotebookClient(nb, timeout=120, kernel_name="python3").execute()
    kinds = [out.get("output_type") for out in nb.cells[0].outputs]
    assert any("image/png" in out.get("data", {}) for out in nb.cells[0].outputs), kinds


@pytest.mark.parametrize("name", LESSONS)
def test_every_lesson_links_the_notation_page(name):
    first = next(c.source for c in _notebook(name).cells if c.cell_type == "markdown")
    assert "(notation.ipynb)" in first, f"{name}: the first cell does not link the notation page"


def _notation_rows():
    table = next(c.source for c in _notebook("notation.ipynb").cells if c.source.lstrip().startswith("| symbol |"))
    return [line.split(" | ")[0].lstrip("| ").strip() for line in table.splitlines()[2:] if line.startswith("|")]


def test_the_notation_page_lists_each_symbol_once():
    symbols = []
    for row in _notation_rows():
        symbols += [part.strip() for part in re.split(r"[,;]", row) if part.strip()]
    repeated = sorted({s for s in symbols if symbols.count(s) > 1})
    assert not repeated, f"symbols listed twice on the notation page: {repeated}"
    for symbol in ("$K$", "$L$", "$\\Sigma$", "$H$", "$\\Lambda$", "$V$", "$W$", "$\\lambda$", "$\\rho$", "$z$"):
        assert symbol in symbols, symbol


def test_no_notebook_speaks_of_a_seed_report():
    for folder in (SOLUTIONS, ROOT / "notebooks"):
        for path in sorted(folder.glob("*.ipynb")):
            assert "seed report" not in path.read_text(encoding="utf-8").lower(), path.name
