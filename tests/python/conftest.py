"""Fixtures of the Python module's tests (run by CTest as `python_tests`).

The module is imported from PYTHONPATH (CTest sets it to the build's python/ folder).
Tests on ../shared read VMAP_SHARED_DIR; without it they are skipped with a message,
unless VMAP_REQUIRE_SHARED_DATA is on (CI), where a missing folder fails them.
"""

import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SAMPLE = REPO / "examples" / "data" / "tum_fr1_rpy_60"


def _on(name):
    return os.environ.get(name, "").upper() in ("1", "ON", "TRUE", "YES")


@pytest.fixture(scope="session")
def repo():
    return REPO


@pytest.fixture(scope="session")
def sample_list():
    """The 60 sample frames kept in the repo, as a TUM rgb.txt."""
    return str(SAMPLE / "rgb.txt")


@pytest.fixture(scope="session")
def sample_frames(sample_list):
    """The 60 sample frames decoded to grey once: a list of (image, timestamp, name)."""
    import vmap

    return list(vmap.frames(sample_list, grey=True))


@pytest.fixture(scope="session")
def shared():
    """../shared (VMAP_SHARED_DIR): its data/ and models/, or a skip saying it is absent."""
    folder = pathlib.Path(os.environ.get("VMAP_SHARED_DIR", str(REPO.parent / "shared")))
    if (folder / "data").is_dir() and (folder / "models").is_dir():
        return folder
    if _on("VMAP_REQUIRE_SHARED_DATA"):
        pytest.fail(f"VMAP_REQUIRE_SHARED_DATA is on but {folder} has no data/ and models/")
    pytest.skip(f"{folder} not found: tests on the shared data are skipped")


@pytest.fixture(scope="session")
def vmap_cli():
    """The built `vmap` command line (VMAP_CLI), to compare the module's results with it."""
    path = os.environ.get("VMAP_CLI", "")
    if path and os.access(path, os.X_OK):
        return path
    pytest.skip("VMAP_CLI is not set to the built vmap program: comparisons with the command line are skipped")
