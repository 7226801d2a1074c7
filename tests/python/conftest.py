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
def fleet_server(tmp_path_factory):
    """A PostgreSQL server of the tests' own on loopback (VMAP_PG_BIN: its programs; run as
    `nobody` under root), stopped at the end: a function giving the URI of a new database.
    Skipped without the programs, unless VMAP_REQUIRE_POSTGRES is on (CI)."""
    import shutil
    import socket
    import subprocess
    import tempfile

    bin_dir = os.environ.get("VMAP_PG_BIN", "")
    if not bin_dir or not os.access(os.path.join(bin_dir, "pg_ctl"), os.X_OK):
        if _on("VMAP_REQUIRE_POSTGRES"):
            pytest.fail("VMAP_REQUIRE_POSTGRES is on but VMAP_PG_BIN names no PostgreSQL server programs")
        pytest.skip("no PostgreSQL server programs (VMAP_PG_BIN): the fleet's tests are skipped")
    folder = tempfile.mkdtemp(prefix="vmap-py-pg-")
    as_server = []
    if os.geteuid() == 0:
        shutil.chown(folder, "nobody", "nogroup")
        as_server = ["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    data = os.path.join(folder, "data")
    run = lambda *args: subprocess.run(as_server + list(args), check=True, capture_output=True)
    run(os.path.join(bin_dir, "initdb"), "-D", data, "-U", "vmap", "--auth=trust", "--no-sync", "-E", "UTF8", "--locale=C")
    run(os.path.join(bin_dir, "pg_ctl"), "-D", data, "-l", os.path.join(folder, "log"), "-w", "-o",
        f"-p {port} -k {folder} -c listen_addresses=127.0.0.1", "start")
    made = []

    def database(name):
        if name not in made:
            run(os.path.join(bin_dir, "createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", "vmap", name)
            made.append(name)
        return f"postgresql://vmap@127.0.0.1:{port}/{name}"

    yield database
    subprocess.run(as_server + [os.path.join(bin_dir, "pg_ctl"), "-D", data, "-m", "immediate", "-w", "stop"],
                   capture_output=True)
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def vmap_cli():
    """The built `vmap` command line (VMAP_CLI), to compare the module's results with it."""
    path = os.environ.get("VMAP_CLI", "")
    if path and os.access(path, os.X_OK):
        return path
    pytest.skip("VMAP_CLI is not set to the built vmap program: comparisons with the command line are skipped")
