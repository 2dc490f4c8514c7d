"""JupyterLab as a user meets it, driven in headless Chromium.

A fresh project in a temporary folder (``pyproject.toml``, ``notebooks/``, an empty
``data/``); JupyterLab serves it on 127.0.0.1 with ``make lab``'s settings; the notebooks
are opened from the file browser and run through the UI (Run > Run All Cells) with their
defaults, in a user's order: sample_lon (its one edit: the tiny test configuration, named
``quick``), analyse_lon, record_optima. Asserted: no error output and no warning, one image
per figure, the interactive LON drawn, the rerun viewer drawn from this machine with no
asset error, ``data/`` in the file browser. The server is stopped by its process id.

Needs Chromium and chromedriver (Debian: ``apt-get install chromium chromium-driver``),
selenium (dev extra), JupyterLab and rerun-notebook (lab extra); skipped otherwise.
``LONLIB_SCREENSHOTS=docs`` also saves small screenshots there (docs/reproducing.md shows them).
WebGL (the rerun viewer, plotly's 3-D) is drawn by SwiftShader, Chromium's CPU renderer.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import pytest
from PIL import Image

from tests.notebooks.test_notebooks import clone_project

REPO = Path(__file__).resolve().parents[2]
BROWSER = next(
    filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None
)
DRIVER = shutil.which("chromedriver")
MODULES = ("selenium", "jupyterlab", "rerun_notebook")


def _missing() -> list[str]:
    missing = [] if BROWSER else ["Chromium (apt-get install chromium)"]
    if not DRIVER:
        missing.append("chromedriver (apt-get install chromium-driver)")
    missing += [f"python module {m}" for m in MODULES if importlib.util.find_spec(m) is None]
    return missing


pytestmark = pytest.mark.skipif(
    bool(_missing()),
    reason="browser test skipped: needs " + ", ".join(_missing()) + "; `make test-browser` "
    "installs the Python side",
)

PANEL = ".jp-NotebookPanel:not(.lm-mod-hidden)"  # the notebook in view
PLOTLY = "application/vnd.plotly.v1+json"
RUN_TIMEOUT = 150  # seconds for one notebook's Run All (tiny experiment, shared CPU)


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A fresh clone's layout, sample_lon set to sample the tiny ``quick.yaml`` with one
    worker, so that it writes data/quick, which the other two notebooks read by default."""
    root = clone_project(tmp_path_factory.mktemp("lab") / "clone")
    book = root / "notebooks" / "sample_lon.ipynb"
    text = book.read_text()
    assert '"config: str = \\"quick\\"' in text and '"workers: int = 2' in text
    text = text.replace('"config: str = \\"quick\\"', '"config: str = \\"quick.yaml\\"')
    book.write_text(text.replace('"workers: int = 2', '"workers: int = 1'))
    return root


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.fixture(scope="module")
def lab(project, tmp_path_factory):
    """JupyterLab serving ``project`` with ``make lab``'s settings (root_dir = the project,
    opening at notebooks/, encrypted kernel connections) on 127.0.0.1 and a free port,
    without the user's Jupyter settings; yields (base URL, token, server log); stopped by
    its pid."""
    home = tmp_path_factory.mktemp("jupyter")
    settings = home / "settings" / "@jupyterlab" / "apputils-extension"
    settings.mkdir(parents=True)
    (settings / "notification.jupyterlab-settings").write_text(
        json.dumps({"fetchNews": "false", "checkForUpdates": False})
    )
    port, token = _free_port(), secrets.token_hex(16)
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
        "JUPYTER_CONFIG_DIR": str(home / "config"),
        "JUPYTER_RUNTIME_DIR": str(home / "runtime"),
        "JUPYTERLAB_SETTINGS_DIR": str(home / "settings"),
        "JUPYTERLAB_WORKSPACES_DIR": str(home / "workspaces"),
    }
    env.pop("RERUN_NOTEBOOK_ASSET", None)  # the default a user has
    command = [
        sys.executable,
        "-m",
        "jupyterlab",
        "--no-browser",
        "--ServerApp.ip=127.0.0.1",
        f"--ServerApp.port={port}",
        "--ServerApp.port_retries=0",
        f"--IdentityProvider.token={token}",
        f"--ServerApp.root_dir={project}",
        "--LabApp.default_url=/lab/tree/notebooks",
        "--MappingKernelManager.transport_encryption=auto",
    ]
    if hasattr(os, "getuid") and os.getuid() == 0:
        command.append("--allow-root")
    log = open(home / "server.log", "w")  # noqa: SIM115 (closed below)
    server = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=project)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                with urllib.request.urlopen(f"{base}/api/status?token={token}", timeout=2):
                    break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(
                        "JupyterLab did not start:\n" + (home / "server.log").read_text()
                    ) from None
                time.sleep(0.5)
        yield base, token, home / "server.log"
    finally:
        os.kill(server.pid, signal.SIGTERM)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.kill(server.pid, signal.SIGKILL)
            server.wait()
        log.close()


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium with a software GPU (swiftshader) for the WebGL viewers."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = BROWSER
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        "--window-size=1280,960",
        "--use-angle=swiftshader",
        "--use-gl=angle",
        "--enable-unsafe-swiftshader",
        "--ignore-gpu-blocklist",
    ):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(executable_path=DRIVER))
    try:
        yield driver
    finally:
        driver.quit()


def _wait(driver, condition, timeout: float, what: str):
    """Wait for ``condition(driver)``; on a timeout fail with the cells' prompts and the path
    of a screenshot."""
    from selenium.common.exceptions import StaleElementReferenceException, TimeoutException
    from selenium.webdriver.support.ui import WebDriverWait

    wait = WebDriverWait(
        driver, timeout, poll_frequency=0.5, ignored_exceptions=[StaleElementReferenceException]
    )
    try:
        return wait.until(condition)
    except TimeoutException:
        shot = Path(tempfile.gettempdir()) / f"lonlib-browser-{secrets.token_hex(4)}.png"
        driver.save_screenshot(str(shot))
        pytest.fail(
            f"timed out after {timeout:.0f} s waiting for {what}; "
            f"prompts {_prompts(driver)}; screenshot {shot}"
        )


def _click_menu(driver, menu: str, command: str) -> None:
    """Click ``menu`` in the menu bar, then its item running ``command``."""
    from selenium.webdriver.common.by import By

    label = f"//div[contains(@class, 'lm-MenuBar-itemLabel') and text()='{menu}']"
    driver.find_element(By.XPATH, label).click()
    item = f"li.lm-Menu-item[data-command='{command}']"
    _wait(driver, lambda d: d.find_element(By.CSS_SELECTOR, item), 10, f"menu item {command}")
    driver.find_element(By.CSS_SELECTOR, item).click()


def _kernel_idle(driver, name: str) -> bool:
    """Whether notebook ``name`` is the one in view, with its cells and an idle kernel."""
    from selenium.webdriver.common.by import By

    status = driver.find_element(By.ID, "jp-main-statusbar").text
    return f"{name}.ipynb" in status and bool(_prompts(driver)) and "| Idle" in status


def _prompts(driver) -> list[str]:
    """The input prompts (``[3]:``, ``[*]:``, ``[ ]:``) of the visible notebook's code cells."""
    return driver.execute_script(
        "return [...document.querySelectorAll(arguments[0])].map(e => e.textContent.trim())",
        f"{PANEL} .jp-CodeCell .jp-InputArea-prompt",
    )


def _finished(driver) -> bool:
    """Whether every code cell of the notebook in view has run (a number in its prompt)."""
    prompts = _prompts(driver)
    return bool(prompts) and all(p[:1] == "[" and p[1:2].isdigit() for p in prompts)


def _screenshot(driver, name: str, tmp_path: Path, focus: str, block: str = "center") -> None:
    """Scroll the notebook to the element ``focus`` (``block``: where it lands) and save a
    screenshot under tmp_path, and a small copy under $LONLIB_SCREENSHOTS (relative to the
    repository)."""
    from selenium.webdriver.common.by import By

    element = driver.find_element(By.CSS_SELECTOR, focus)
    driver.execute_script(
        "arguments[0].scrollIntoView({block: arguments[1]});"
        "document.documentElement.scrollTo(0, 0); document.body.scrollTo(0, 0);",
        element,
        block,
    )
    time.sleep(1)
    path = tmp_path / f"{name}.png"
    driver.save_screenshot(str(path))
    folder = os.environ.get("LONLIB_SCREENSHOTS")
    if folder:
        target = (REPO / folder).resolve()
        target.mkdir(parents=True, exist_ok=True)
        with Image.open(path) as image:
            small = image.convert("RGB").resize((image.width * 3 // 4, image.height * 3 // 4))
            small.quantize(colors=128).save(target / f"lab_{name}.png", optimize=True)


def _file_item(name: str) -> str:
    """XPath of entry ``name`` in JupyterLab's file browser."""
    return f"//li[contains(@class, 'jp-DirListing-item')][.//span[text()='{name}']]"


def _run_all(driver, name: str) -> None:
    """Open notebook ``name`` from the file browser, Run > Run All Cells, wait for every
    cell, File > Save."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    ActionChains(driver).double_click(
        driver.find_element(By.XPATH, _file_item(f"{name}.ipynb"))
    ).perform()
    _wait(driver, lambda d: _kernel_idle(d, name), 120, f"{name} to open with an idle kernel")
    _click_menu(driver, "Run", "runmenu:run-all")
    _wait(driver, _finished, RUN_TIMEOUT, f"Run All of {name}")
    _click_menu(driver, "File", "docmanager:save")
    _wait(driver, lambda d: "jp-mod-dirty" not in _active_tab(d), 30, f"{name} to be saved")


def _drawn(driver, selector: str) -> bool:
    """Whether the canvas ``selector`` is large and shows a picture (many colours), not a
    blank or single-colour area."""
    from selenium.webdriver.common.by import By

    canvases = driver.find_elements(By.CSS_SELECTOR, selector)
    if not canvases or canvases[0].size["width"] < 400 or canvases[0].size["height"] < 300:
        return False
    with Image.open(io.BytesIO(canvases[0].screenshot_as_png)) as image:
        return len(image.convert("RGB").getcolors(maxcolors=1 << 20) or ()) > 50


def _active_tab(driver) -> str:
    """The class of the main area's current tab (``jp-mod-dirty`` while unsaved)."""
    return driver.execute_script(
        "return document.querySelector('.lm-DockPanel-tabBar .lm-mod-current').className"
    )


def _check_outputs(driver, book_path: Path, images: int, plots: int) -> None:
    """No error output and no warning on stderr in the saved notebook; ``images`` figures
    (PNG) and ``plots`` interactive plotly figures, saved and drawn in the page."""
    from selenium.webdriver.common.by import By

    book = json.loads(book_path.read_text())
    outputs = [out for cell in book["cells"] for out in cell.get("outputs", [])]
    errors = [out for out in outputs if out["output_type"] == "error"]
    assert not errors, "\n".join(f"{e['ename']}: {e['evalue']}" for e in errors)
    stderr = "".join("".join(out["text"]) for out in outputs if out.get("name") == "stderr")
    assert "Warning" not in stderr, stderr
    # JupyterLab's plotly renderer saves a PNG snapshot beside the figure: not a figure.
    data = [out.get("data", {}) for out in outputs]
    assert sum("image/png" in d and PLOTLY not in d for d in data) == images
    assert sum(PLOTLY in d for d in data) == plots
    assert len(driver.find_elements(By.CSS_SELECTOR, f"{PANEL} .jp-RenderedImage img")) == images
    assert len(driver.find_elements(By.CSS_SELECTOR, f"{PANEL} .js-plotly-plot")) == plots


def test_notebooks_run_all_with_their_defaults_in_jupyterlab(project, lab, browser, tmp_path):
    """sample_lon -> analyse_lon -> record_optima, as a user runs them after a clone."""
    from selenium.webdriver.common.by import By

    base, token, server_log = lab
    browser.get(f"{base}/?token={token}")  # the default URL: notebooks/, as `make lab` opens
    _wait(
        browser,
        lambda d: d.find_elements(By.XPATH, _file_item("sample_lon.ipynb")),
        120,
        "JupyterLab",
    )
    browser.get_log("browser")
    _run_all(browser, "sample_lon")
    _check_outputs(browser, project / "notebooks" / "sample_lon.ipynb", images=1, plots=0)
    assert (project / "data" / "quick" / "manifest.json").exists()
    assert not (project / "notebooks" / "data").exists()  # the kernel runs in notebooks/
    _screenshot(browser, "sample_lon", tmp_path, f"{PANEL} .widget-hprogress", "start")

    # One p sampled: Fig. 2, and Figs. 3 (PNG + interactive), 4 and 5 for it; then the
    # conditioning: Figs. 4 and 5 on the robust estimate and the retention curve.
    _run_all(browser, "analyse_lon")
    _check_outputs(browser, project / "notebooks" / "analyse_lon.ipynb", images=7, plots=1)
    _screenshot(browser, "analyse_lon", tmp_path, focus=f"{PANEL} .js-plotly-plot")

    _run_all(browser, "record_optima")
    _check_outputs(browser, project / "notebooks" / "record_optima.ipynb", images=0, plots=0)
    assert list((project / "data" / "quick" / "recordings").glob("*.rrd"))
    canvas = f"{PANEL} .jp-OutputArea-output canvas"
    _wait(browser, lambda d: _drawn(d, canvas), 60, "the rerun viewer to draw")
    assert "Failed to fetch" not in browser.find_element(By.CSS_SELECTOR, PANEL).text
    log = [entry["message"] for entry in browser.get_log("browser")]
    (tmp_path / "console.log").write_text("\n".join(log))
    # Offline, only the viewer's update check (api.github.com) may fail to load.
    problems = [
        m
        for m in log
        if "Application ID" in m or ("Failed to load resource" in m and "github.com" not in m)
    ]
    assert not problems, problems
    _screenshot(browser, "record_optima", tmp_path, focus=canvas)

    # The lab's root is the project: data/ beside notebooks/, its files served.
    def home_lists_data(driver) -> bool:
        if driver.find_elements(By.XPATH, _file_item("data")):
            return True
        # clicked (again) until listed: a click while the viewer draws can be lost
        driver.find_element(By.CSS_SELECTOR, ".jp-BreadCrumbs-home").click()
        return False

    _wait(browser, home_lists_data, 30, "data/ listed")
    figure = f"{base}/files/data/quick/figures/fig3_lon_p=0.0001.html?token={token}"
    with urllib.request.urlopen(figure, timeout=30) as response:
        assert response.status == 200 and b"plotly" in response.read()
    assert "without encryption" not in server_log.read_text()
