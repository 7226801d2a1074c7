"""Fixtures of the page's browser tests (run by CTest as `view_tests`): headless Chromium
driven by Selenium (Debian's chromium, chromium-driver and python3-selenium), the built
`vmap` program (VMAP_CLI), and the Python module's fixtures (tests/python/conftest.py:
the sample frames, a PostgreSQL server of the tests' own)."""

import importlib.util
import json
import os
import pathlib
import shutil
import subprocess

import pytest

_here = pathlib.Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("vmap_python_conftest", _here.parent / "python" / "conftest.py")
_python = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_python)
repo = _python.repo
sample_list = _python.sample_list
fleet_server = _python.fleet_server
vmap_cli = _python.vmap_cli
shared = _python.shared

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"


@pytest.fixture(scope="session")
def browser():
    """One headless Chromium for the session (a page is opened per test), with the
    browser's console kept so that a test can assert it logged no error."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        pytest.skip("python3-selenium is not installed: the browser tests are skipped")
    if not (os.access(CHROMIUM, os.X_OK) and os.access(CHROMEDRIVER, os.X_OK)):
        pytest.skip("chromium and chromium-driver are not installed: the browser tests are skipped")
    o = Options()
    o.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1100,900",
              "--hide-scrollbars", "--force-device-scale-factor=1"):
        o.add_argument(a)
    o.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=o)
    yield driver
    driver.quit()


def run_vmap(cli, *args, check=True):
    r = subprocess.run([cli, *map(str, args)], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"vmap {' '.join(map(str, args))} exited {r.returncode}:\n{r.stderr}")
    return r


def tum_poses(path, times, up_axis, shift=(0.0, 0.0, 0.0)):
    """A TUM trajectory of the sample's frame times with known geometry: the camera walks
    a circle of radius 1 m in the floor plane of `up_axis` ('y' or 'z', world up is +),
    looking along the circle's tangent, its image's up (-y of the camera) along world up."""
    import numpy as np

    lines = []
    for i, t in enumerate(times):
        a = 2 * np.pi * i / len(times)
        if up_axis == "y":
            up = np.array([0.0, 1.0, 0.0])
            pos = np.array([np.cos(a), 0.02 * np.sin(3 * a), np.sin(a)])
            forward = np.array([-np.sin(a), 0.0, np.cos(a)])
        else:
            up = np.array([0.0, 0.0, 1.0])
            pos = np.array([np.cos(a), np.sin(a), 0.02 * np.sin(3 * a)])
            forward = np.array([-np.sin(a), np.cos(a), 0.0])
        pos = pos + np.array(shift)
        y = -up
        z = forward
        x = np.cross(y, z)
        rot = np.stack([x, y, z], axis=1)  # camera to world: columns are the camera's axes
        q = _quaternion(rot)
        lines.append(f"{t} {pos[0]:.6f} {pos[1]:.6f} {pos[2]:.6f} {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}")
    pathlib.Path(path).write_text("\n".join(lines) + "\n")


def _quaternion(r):
    """(qx, qy, qz, qw) of a rotation matrix (TUM order)."""
    import numpy as np

    w = np.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = np.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2
    y = np.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2
    z = np.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2
    x = np.copysign(x, r[2, 1] - r[1, 2])
    y = np.copysign(y, r[0, 2] - r[2, 0])
    z = np.copysign(z, r[1, 0] - r[0, 1])
    return x, y, z, w


def sample_times(sample_list):
    return [line.split()[0] for line in pathlib.Path(sample_list).read_text().splitlines() if line and line[0] != "#"]


@pytest.fixture(scope="session")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("view")


@pytest.fixture(scope="session")
def two_runs(vmap_cli, sample_list, work):
    """A memory store of the 60 sample frames mapped twice (two sessions, no poses): loops
    between the runs."""
    memory = work / "two_runs.vmdb"
    run_vmap(vmap_cli, "build", sample_list, "--memory", memory)
    run_vmap(vmap_cli, "build", sample_list, "--memory", memory, "--session", "new")
    info = json.loads(run_vmap(vmap_cli, "memory", "info", memory, "--json").stdout)
    assert len(info["sessions"]) == 2 and len(info["loops"]) > 0, "the sample mapped twice closes loops"
    return memory, info


@pytest.fixture(scope="session")
def posed(vmap_cli, sample_list, work):
    """The sample frames mapped twice with poses of known geometry: a circle in the x-z
    plane with +y up, the second run's shifted by 0.5 m along x."""
    times = sample_times(sample_list)
    tum_poses(work / "poses_a.txt", times, "y")
    tum_poses(work / "poses_b.txt", times, "y", shift=(0.5, 0.0, 0.0))
    memory = work / "posed.vmdb"
    run_vmap(vmap_cli, "build", sample_list, "--memory", memory, "--poses", work / "poses_a.txt")
    run_vmap(vmap_cli, "build", sample_list, "--memory", memory, "--session", "new", "--poses", work / "poses_b.txt")
    info = json.loads(run_vmap(vmap_cli, "memory", "info", memory, "--json").stdout)
    assert all(k["pose"] is not None for k in info["key_images"])
    return memory, info


def open_page(browser, folder):
    """Opens folder/index.html and waits until the page says it is ready."""
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get_log("browser")  # drop what earlier pages logged
    browser.get((pathlib.Path(folder) / "index.html").resolve().as_uri())
    WebDriverWait(browser, 20).until(lambda d: d.execute_script("return !!(window.vmapView && window.vmapView.ready)"))
    return browser


def console_errors(browser):
    return [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def hook(browser, expression):
    return browser.execute_script("return window.vmapView." + expression)


def fresh(path):
    path = pathlib.Path(path)
    if path.exists():
        shutil.rmtree(path)
    return path
