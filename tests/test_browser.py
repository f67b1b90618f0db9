"""The stepper page in a real browser: Voila serves visla_edu/stepper_app.ipynb, Playwright
drives Debian's chromium (headless) like a user: step, move the slider, change the dataset.

Skipped (with the reason) when /usr/bin/chromium, playwright or voila is missing.
"""

import importlib.util
import socket
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

pytestmark = pytest.mark.browser

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
START_TIMEOUT = 60  # s, Voila up and the page's kernel done
ACTION_TIMEOUT = 20_000  # ms, one widget round trip (filter step + redraw)


def _skip_reason():
    if not CHROMIUM.is_file():
        return f"{CHROMIUM} is missing (apt-get install chromium)"
    if importlib.util.find_spec("playwright") is None:
        return "the python package playwright is not installed"
    if importlib.util.find_spec("voila") is None:
        return "voila is not installed (pip install voila)"
    return None


def _free_port():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _wait_until_answers(url, proc, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"voila exited with code {proc.returncode} before answering {url}")
        try:
            # any HTTP answer means the server is up (GET / would execute the page)
            with urllib.request.urlopen(url + "api", timeout=2):
                return
        except urllib.error.HTTPError:
            return
        except OSError:
            time.sleep(0.3)
    raise TimeoutError(f"voila did not answer {url} within {timeout} s")


def _stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


@pytest.fixture(scope="module")
def page_url(tmp_path_factory):
    reason = _skip_reason()
    if reason:
        pytest.skip(reason)
    from visla_edu.stepper.app import serve

    port = _free_port()
    log = tmp_path_factory.mktemp("voila") / "voila.log"
    with open(log, "wb") as out:
        proc = serve(port=port, dataset="sim-tiny", stdout=out, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}/"
    try:
        _wait_until_answers(url, proc, START_TIMEOUT)
        yield url
    finally:
        _stop(proc)
        if proc.returncode not in (0, -15, 143, None) and log.is_file():
            print(log.read_text(errors="replace")[-3000:])


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser, page_url):
    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.set_default_timeout(ACTION_TIMEOUT)
    page.goto(page_url, timeout=START_TIMEOUT * 1000)
    page.wait_for_selector(".visla-stepper .widget-output img", timeout=START_TIMEOUT * 1000)
    yield page
    page.close()


STATUS = ".visla-stepper .widget-html-content"
IMAGE = ".visla-stepper .widget-output img"


def _status(page):
    return page.inner_text(STATUS)


def _wait_for_status(page, text):
    page.wait_for_function(
        "([sel, text]) => { const e = document.querySelector(sel); return e && e.innerText.includes(text); }",
        arg=[STATUS, text])


def _wait_for_new_image(page, old_src):
    page.wait_for_function(
        "([sel, old]) => { const e = document.querySelector(sel); return e && e.src && e.src !== old; }",
        arg=[IMAGE, old_src])
    return page.get_attribute(IMAGE, "src")


def test_page_steps_and_moves_the_slider(page):
    assert "t = 0 / 59" in _status(page)
    src0 = page.get_attribute(IMAGE, "src")
    assert src0.startswith("data:image/png")

    page.get_by_role("button", name="step ▶").click()
    _wait_for_status(page, "t = 1 / 59")
    src1 = _wait_for_new_image(page, src0)
    assert src1 != src0

    page.get_by_role("button", name="+10 ▶▶").click()
    _wait_for_status(page, "t = 11 / 59")
    src2 = _wait_for_new_image(page, src1)

    # the slider, with the keyboard as a user would: focus its handle, press End / arrow keys
    handle = page.locator(".visla-stepper .widget-slider .noUi-handle").first
    handle.focus()
    page.keyboard.press("ArrowLeft")
    _wait_for_status(page, "t = 10 / 59")
    src3 = _wait_for_new_image(page, src2)
    assert src3 not in (src0, src1, src2)

    page.get_by_role("button", name="◀ back").click()
    _wait_for_status(page, "t = 9 / 59")


def test_page_changes_dataset_and_mode(page):
    src0 = page.get_attribute(IMAGE, "src")
    selects = page.locator(".visla-stepper select")
    labels = selects.nth(0).locator("option").all_inner_texts()
    small = next(label for label in labels if label.startswith("sim-small"))
    selects.nth(0).select_option(label=small)
    _wait_for_status(page, "t = 0 / 299")
    src1 = _wait_for_new_image(page, src0)

    selects.nth(1).select_option(label="visual-inertial odometry")
    page.wait_for_function(
        "(sel) => { const e = document.querySelector(sel); return e && e.innerText.includes('renders'); }",
        arg=STATUS)
    page.get_by_role("button", name="step ▶").click()
    _wait_for_status(page, "t = 1 / 299")
    _wait_for_new_image(page, src1)
    shot = page.locator(".visla-stepper .widget-output").screenshot()
    assert shot.startswith(b"\x89PNG") and len(shot) > 10_000
