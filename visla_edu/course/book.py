"""The course site: ``visla-edu book DIR`` builds the lessons as static HTML pages (TEACHING.md, 8).

An index and one page per notebook of ``solutions/`` (file-name order): its **student edition**
(:func:`visla_edu.course.release.student_notebook`), never the solutions, executed by nbclient with errors
allowed, so no output carries a model answer. Exercise and graded cells lose their outputs; an error in any
other cell stops the build (:class:`BookError`); widgets become the figures they held. Sphinx with myst-nb
renders (executes nothing); nothing is downloaded (MathJax 2 comes from ``jupyter-server-mathjax``). Built
beside ``DIR`` and moved into place, so an interrupted build leaves the previous site whole.
"""

import contextlib
import importlib.util
import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from visla_edu.course import release

__all__ = ["BookError", "BOOK_PACKAGES", "STUDENT_FOLDER", "CELL_TIMEOUT", "require_book_tools", "notebook_paths",
           "check_site_folder", "student_page", "build_book", "default_solutions"]

#: The packages of the ``book`` extra that the build imports: import name -> distribution name.
BOOK_PACKAGES = {"sphinx": "sphinx", "myst_nb": "myst-nb", "sphinx_book_theme": "sphinx-book-theme",
                 "jupyter_server_mathjax": "jupyter-server-mathjax", "nbclient": "nbclient"}
#: The repository's folder of the student notebooks (:data:`visla_edu.course.STUDENT_NOTEBOOKS`):
#: the Binder and Colab buttons of a page open ``STUDENT_FOLDER/<page>.ipynb`` of the repository.
STUDENT_FOLDER = "visla_edu/course/notebooks"
#: Seconds one cell may run (as the notebook tests allow).
CELL_TIMEOUT = 600
TITLE = "Visual-inertial SLAM with an EKF"

_WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"
_WIDGET_STATE = "application/vnd.jupyter.widget-state+json"
_WIDGET_NOTE = ("*An interactive widget was here: run the notebook in Jupyter (or on Binder or Colab) to use it. "
                "The figure below is what it showed when this page was made.*")
_DATA_VARIABLES = ("VISLA_EDU_DATA", "VISLA_EDU_DATASET")
#: MathJax 2 as Jupyter's classic notebook set it up for the fonts that jupyter-server-mathjax ships
#: (STIX-Web only), reading the delimiters Sphinx writes around math.
_MATHJAX2_CONFIG = {
    "tex2jax": {"inlineMath": [["\\(", "\\)"]], "displayMath": [["\\[", "\\]"]], "processEscapes": False,
                "processEnvironments": False, "processRefs": False},
    "HTML-CSS": {"availableFonts": [], "imageFont": None, "preferredFont": None, "webFont": "STIX-Web"},
    "menuSettings": {"zoom": "None"},
}
#: MathJax 2's hidden MathML copy of each formula (for screen readers) asks for TeX fonts that the local
#: MathJax does not ship; it is never seen, so it takes the page's font and nothing is fetched in vain.
_CSS = ".MJX_Assistive_MathML, .MJX_Assistive_MathML * { font-family: inherit !important; }\n"
_REPOSITORY = re.compile(r"https://(github|gitlab)\.com/[\w.-]+/[\w.-]+")


class BookError(RuntimeError):
    """The build stopped on valid input: a notebook failed outside its exercises, or Sphinx failed (exit 1, not 2)."""

    failed = True


def require_book_tools():
    """Check that the packages of the ``book`` extra are installed; a ValueError names those missing and the extra."""
    missing = [dist for module, dist in BOOK_PACKAGES.items() if importlib.util.find_spec(module) is None]
    if missing:
        raise ValueError(f"the course site needs {', '.join(missing)}: install visla-edu[book] "
                         "(in a clone: pip install -e \".[book]\")")


def default_solutions():
    """The repository's ``solutions/`` folder (:data:`visla_edu.course.release.SOLUTIONS`)."""
    return release.SOLUTIONS


def notebook_paths(src_dir):
    """The notebooks of ``src_dir`` in file-name order (``*.ipynb``, not hidden); FileNotFoundError if none."""
    src_dir = Path(src_dir)
    if not src_dir.is_dir():
        raise FileNotFoundError(f"solutions folder {src_dir} not found: build the book in a clone of the repository, "
                                "or pass --src")
    paths = sorted(p for p in src_dir.glob("*.ipynb") if not p.name.startswith("."))
    if not paths:
        raise FileNotFoundError(f"no notebooks (*.ipynb) in {src_dir}")
    return paths


def check_site_folder(out_dir):
    """``out_dir`` as an absolute path if new, empty or a site built before (has ``.buildinfo``); else ValueError."""
    out_dir = Path(out_dir).expanduser().absolute()
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"{out_dir} is a file, not a folder: give a new or empty folder for the site")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / ".buildinfo").is_file():
        raise ValueError(f"{out_dir} is not empty and is not a site built by visla-edu book (no .buildinfo): give a "
                         "new or empty folder (a rebuild replaces everything in it)")
    return out_dir


@contextlib.contextmanager
def _staging(out_dir):
    """A new folder beside ``out_dir`` to build in (removed at the end); ValueError if none can be made."""
    parent = out_dir.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.building-", dir=parent))
    except OSError as err:
        raise ValueError(f"cannot write the site {out_dir}: {parent} is not writable ({err.strerror or err}); "
                         "give a folder where you may write") from None
    try:
        yield staging
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _kernel_env(course_data):
    """The environment of the notebook kernels: figures inline, course data as asked."""
    env = dict(os.environ)
    env.pop("MPLBACKEND", None)  # the kernel's inline backend, not Agg, so plots become figures
    if not course_data:
        for name in _DATA_VARIABLES:
            env.pop(name, None)
    return env


def _execute(nb, work_dir, course_data):
    """Run every cell of ``nb`` in place (errors kept as outputs, widget state kept)."""
    from nbclient import NotebookClient

    client = NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3", allow_errors=True,
                            store_widget_state=True, resources={"metadata": {"path": str(work_dir)}})
    # the kernel's own log (e.g. its transport warning) is not the user's business; cells' output is kept
    client.execute(env=_kernel_env(course_data), stderr=subprocess.DEVNULL)


def _is_exercise(cell):
    meta = cell.metadata.get("nbgrader", {})
    return bool(meta.get("solution") or meta.get("grade"))


def _blank_exercises(nb, name):
    """Remove the outputs of exercise and graded cells; :class:`BookError` for an error anywhere else."""
    for index, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        if _is_exercise(cell):
            cell.outputs, cell.execution_count = [], None
            continue
        errors = [output for output in cell.outputs if output.output_type == "error"]
        if errors:
            raise BookError(f"{name} cell {index} raised {errors[0].ename}: {errors[0].evalue} (outside the "
                            "exercises, the student edition must run: fix the notebook in solutions/)")


def _widget_images(model_id, state):
    """The base64 PNGs of the ``Output`` widgets in widget ``model_id`` and its children, in order."""
    model = state.get(model_id, {}).get("state", {})
    images = [out["data"]["image/png"] for out in model.get("outputs", []) if "image/png" in out.get("data", {})]
    for child in model.get("children", []):
        images += _widget_images(str(child).removeprefix("IPY_MODEL_"), state)
    return images


def _freeze_widgets(nb):
    """Replace each widget output by its figures and a note (nothing if it holds no figure: a progress bar)."""
    import nbformat

    state = nb.metadata.pop("widgets", {}).get(_WIDGET_STATE, {}).get("state", {})
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        outputs = []
        for output in cell.outputs:
            view = output.get("data", {}).get(_WIDGET_VIEW)
            if view is None:
                outputs.append(output)
            elif images := _widget_images(view.get("model_id", ""), state):
                outputs.append(nbformat.v4.new_output("display_data", data={"text/markdown": _WIDGET_NOTE,
                                                                            "text/plain": _WIDGET_NOTE}))
                outputs += [nbformat.v4.new_output("display_data", data={"image/png": png}) for png in images]
        cell.outputs = outputs


def student_page(path, work_dir, course_data=True):
    """The page (a NotebookNode) of one notebook: its student edition, executed, exercises blank, widgets frozen.

    ``path``: a solution notebook; ``work_dir``: the kernel's folder. :class:`BookError` when a cell outside the
    exercises raised, ValueError for unbalanced markers (:func:`visla_edu.course.release.student_notebook`).
    """
    import nbformat

    nb = release.student_notebook(nbformat.read(str(path), as_version=4), path.name)
    if any(cell.cell_type == "code" and cell.source.strip() for cell in nb.cells):
        _execute(nb, work_dir, course_data)
    _blank_exercises(nb, path.name)
    _freeze_widgets(nb)
    return nb


def _check_repository(repository, branch):
    if repository is not None and not _REPOSITORY.fullmatch(repository.rstrip("/")):
        raise ValueError(f"--repository {repository}: give the repository's web address, "
                         "https://github.com/OWNER/NAME (or gitlab.com)")
    if not re.fullmatch(r"[\w.-]+(/[\w.-]+)*", branch):
        raise ValueError(f"--branch {branch!r}: give a branch name such as main (letters, digits, . _ - and /)")


def _launch_text(repository, branch):
    """The index's section on running the notebooks (with Binder and Colab when the repository is known)."""
    lines = ["## Run the notebooks yourself", "",
             "Each page is a notebook: install visla-edu as the repository's README says and open the notebooks in "
             "JupyterLab. The exercises are yours to write; the check under each one says what is still wrong.", ""]
    if repository is None:
        return lines
    repository = repository.rstrip("/")
    colab = ("or on Colab, where the notebook's first cell must install the package:" if "github.com" in repository
             else "or, in any Jupyter of your own, after installing the package:")
    lines += ["Or run them online, without installing anything (and without the course data): "
              f"[Binder]({_binder_url(repository, branch)}) builds the course with the package and opens your "
              f"folder `work/` of the notebooks; the rocket button of each page opens that page on Binder {colab}", "",
              "```python", f'%pip install "visla-edu @ git+{repository}@{branch}"', "```", "",
              "Work saved on Binder or Colab is lost when the session ends: download your notebooks.", ""]
    return lines


def _binder_url(repository, branch):
    """mybinder.org's address of ``repository`` at ``branch``, opening JupyterLab in ``work/`` (binder/postBuild)."""
    host, path = repository.split("://", 1)[1].split("/", 1)
    provider = f"gh/{path}" if host == "github.com" else f"gl/{path.replace('/', '%2F')}"
    return f"https://mybinder.org/v2/{provider}/{branch}?urlpath=lab/tree/work"


def _index_text(pages, repository, branch, course_data):
    """The markdown of the index page: what the site is, how to run it, the table of contents."""
    data = ("with the course data" if course_data and os.environ.get("VISLA_EDU_DATA")
            else "without the course data (its cells say they skip, as on Binder)")
    lines = [f"# {TITLE}", "",
             "The lessons of visla-edu, a course on visual-inertial SLAM with an extended Kalman filter (the "
             "UCSD ECE276A project). Each page derives one piece, asks you to write a few small functions, "
             "then uses the library's version of them on simulated and real drives.", "",
             "These pages are the **student edition**: the exercises are stubs, their graded checks are shown "
             "without output, and the answers to the questions are yours to write. Everything else was run as you "
             f"will run it, {data}; an interactive widget is shown as the figure it drew.", ""]
    lines += _launch_text(repository, branch)
    lines += ["```{toctree}", ":maxdepth: 1", ":caption: Notebooks", "", *pages, "```", ""]
    return "\n".join(lines)


def _theme_options(repository, branch):
    options = {"show_toc_level": 2, "use_download_button": True, "home_page_in_toc": True}
    if repository is not None:
        options.update(repository_url=repository.rstrip("/"), repository_branch=branch, path_to_docs=STUDENT_FOLDER,
                       use_repository_button=True,
                       launch_buttons={"binderhub_url": "https://mybinder.org", "notebook_interface": "jupyterlab",
                                       **({"colab_url": "https://colab.research.google.com"}
                                          if "github.com" in repository else {})})
    return options


def _sphinx_settings(repository, branch):
    """Sphinx's configuration (no conf.py); ``githubpages`` only writes ``.nojekyll``, so Pages serves ``_static``."""
    return {
        "project": TITLE, "html_title": TITLE, "author": "visla-edu",
        "extensions": ["myst_nb", "sphinx.ext.mathjax", "sphinx.ext.githubpages"],
        "exclude_patterns": ["_static", "**.ipynb_checkpoints"],
        "html_theme": "sphinx_book_theme", "html_theme_options": _theme_options(repository, branch),
        "html_static_path": ["_static"], "html_css_files": ["visla-book.css"],
        "nb_execution_mode": "off", "nb_ipywidgets_js": {}, "nb_merge_streams": True,
        "myst_enable_extensions": ["dollarmath", "amsmath"], "myst_update_mathjax": False,
        "mathjax_path": "mathjax/MathJax.js?config=TeX-AMS-MML_HTMLorMML-full", "mathjax2_config": _MATHJAX2_CONFIG,
    }


def _write_sources(src, pages, index_text):
    """The Sphinx source folder: the index, the executed pages, MathJax in ``_static``."""
    import jupyter_server_mathjax
    import nbformat

    (src / "_static").mkdir(parents=True)
    shutil.copytree(Path(jupyter_server_mathjax.__file__).parent / "static", src / "_static" / "mathjax")
    (src / "_static" / "visla-book.css").write_text(_CSS, encoding="utf-8")
    for name, nb in pages.items():
        nbformat.write(nb, str(src / f"{name}.ipynb"))
    (src / "index.md").write_text(index_text, encoding="utf-8")


def _run_sphinx(src, out, doctrees, settings):
    """Build the HTML; return Sphinx's warnings (lines; Python's deprecation warnings are the theme's, not shown)."""
    import io
    import warnings

    from sphinx.application import Sphinx
    from sphinx.errors import SphinxError

    log = io.StringIO()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", PendingDeprecationWarning)
            app = Sphinx(str(src), None, str(out), str(doctrees), "html", confoverrides=settings,
                         status=io.StringIO(), warning=log, freshenv=True)
            app.build()
    except SphinxError as err:
        raise BookError(f"Sphinx failed: {err}") from err
    return [line for line in log.getvalue().splitlines() if line.strip()]


def _pages(paths, course_data, log):
    """``{page name: executed student edition}``, the kernels working in a short system temporary folder."""
    pages = {}
    with tempfile.TemporaryDirectory(prefix="visla-edu-book-") as work:
        for path in paths:
            started = time.perf_counter()
            pages[path.stem] = student_page(path, work, course_data)
            code = any(cell.cell_type == "code" for cell in pages[path.stem].cells)
            log(f"{'executed' if code else 'read'} {path.name} ({time.perf_counter() - started:.1f} s)")
    return pages


def build_book(out_dir, src_dir=None, course_data=True, repository=None, branch="main", log=print):
    """Build the course site into ``out_dir``; return ``out_dir / "index.html"``.

    ``src_dir``: the solution notebooks (default ``solutions/``); ``course_data``: let kernels see
    ``VISLA_EDU_DATA`` (False, ``--no-course-data``: hidden, as on Binder, so nothing non-redistributable
    shows); ``repository``: ``https://github.com/OWNER/NAME`` (or gitlab.com) for Binder and Colab buttons
    opening ``branch``; ``log``: called with each progress line.

    ValueError (no ``book`` extra, bad ``out_dir`` or ``repository``), FileNotFoundError (no solutions),
    :class:`BookError` (a notebook failed outside its exercises, or Sphinx failed).
    """
    require_book_tools()
    _check_repository(repository, branch)
    out_dir = check_site_folder(out_dir)
    paths = notebook_paths(default_solutions() if src_dir is None else src_dir)
    with _staging(out_dir) as staging:
        src = staging / "source"
        pages = _pages(paths, course_data, log)
        _write_sources(src, pages, _index_text(list(pages), repository, branch, course_data))
        site = staging / "site"
        for warning in _run_sphinx(src, site, staging / "doctrees", _sphinx_settings(repository, branch)):
            log(f"sphinx: {warning}")
        if out_dir.is_dir():  # the old site goes into the staging folder, removed with it
            out_dir.rename(staging / "previous-site")
        site.rename(out_dir)
    return out_dir / "index.html"
