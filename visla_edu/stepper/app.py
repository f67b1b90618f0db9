"""The stepper as a page of its own (``visla-edu stepper --port 8866``): the Voila app notebook and its server.

The page, ``visla_edu/stepper_app.ipynb`` (package data), is one cell showing a
:class:`~visla_edu.stepper.widget.StepperWidget`.
"""

import importlib.util
import os
import signal
import subprocess
import sys
from pathlib import Path

__all__ = ["serve", "app_notebook_path"]


def app_notebook_path():
    """Path of ``stepper_app.ipynb`` in the installed package: absolute, links resolved, existence not checked."""
    return Path(__file__).resolve().parent.parent / "stepper_app.ipynb"


def serve(port=8866, open_browser=False, data_dir=None, dataset=None, mode=None, wait=False, **popen_options):
    """Serve the stepper as a standalone page with Voila (``voila stepper_app.ipynb --port N``).

    Parameters
    ----------
    data_dir : str or os.PathLike, optional
        Folder of the course files, passed to the page as ``VISLA_EDU_DATA``.
    dataset, mode : str, optional
        What the page opens with (default ``"sim"``, ``"slam"``), via ``VISLA_EDU_STEPPER_DATASET``/``_MODE``.
    wait : bool
        Block until the server exits (Ctrl-C or SIGTERM stop it, never leaving Voila behind); else return at once.

    Returns
    -------
    subprocess.Popen
        The Voila process (the page is at ``http://localhost:<port>/``; ``terminate()`` stops it).
    """
    notebook = app_notebook_path()
    if not notebook.is_file():
        raise FileNotFoundError(f"the stepper page {notebook} is missing from the installed package")
    cmd = [sys.executable, "-m", "voila", str(notebook), f"--port={int(port)}"]
    if not open_browser:
        cmd.append("--no-browser")
    env = dict(os.environ)
    if data_dir is not None:
        from visla_edu import data
        from visla_edu._files import expand_user

        env[data.ENV_VAR] = str(expand_user(data_dir).resolve())
    for name, value in (("VISLA_EDU_STEPPER_DATASET", dataset), ("VISLA_EDU_STEPPER_MODE", mode)):
        if value is not None:
            env[name] = str(value)
    if importlib.util.find_spec("voila") is None:
        raise RuntimeError("the stepper page needs Voila: pip install voila")
    proc = subprocess.Popen(cmd, env=env, cwd=str(notebook.parent), **popen_options)
    if wait:
        _wait_and_stop(proc)
    return proc


def _interrupt(signum, frame):
    """SIGTERM handler while the server runs: stop as Ctrl-C does."""
    raise KeyboardInterrupt


def _wait_and_stop(proc):
    """Wait for the Voila process; on Ctrl-C or SIGTERM stop it (killed if it lingers 10 s)."""
    try:
        previous = signal.signal(signal.SIGTERM, _interrupt)
    except ValueError:  # not the main thread: signals cannot be handled here
        previous = None
    try:
        proc.wait()
    except KeyboardInterrupt:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
