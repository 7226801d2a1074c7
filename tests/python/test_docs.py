"""Runs the Python shown in README.md and examples/python.md as a user would paste it:
every ```python block as a script, and every `PYTHONPATH=build/release/python python3 ...`
command line, from a scratch folder laid out like the repository (examples/ and ../shared
reached through links, build/release/examples/vmap the built program), with this build's
module on PYTHONPATH."""

import os
import pathlib
import re
import shlex
import subprocess
import sys

import pytest

import vmap

REPO = pathlib.Path(__file__).resolve().parents[2]
PAGES = [REPO / "README.md", REPO / "examples" / "python.md"]
PREFIX = "PYTHONPATH=build/release/python python3 "
BLOCK = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)


def items():
    for page in PAGES:
        for n, (lang, body) in enumerate(BLOCK.findall(page.read_text())):
            if lang == "python":
                yield pytest.param(page.name, "script", body, id=f"{page.name}-python-{n}")
            elif lang in ("sh", "bash", ""):
                for line in body.splitlines():
                    if line.startswith(PREFIX):
                        yield pytest.param(page.name, "command", line, id=f"{page.name}-sh-{n}")


def test_the_pages_show_python():
    found = list(items())
    assert sum(p.values[1] == "script" for p in found) >= 3
    assert sum(p.values[1] == "command" for p in found) >= 2


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    root = tmp_path_factory.mktemp("docs")
    repo = root / "repo"
    (repo / "build" / "release" / "examples").mkdir(parents=True)
    (repo / "examples").symlink_to(REPO / "examples")
    shared = pathlib.Path(os.environ.get("VMAP_SHARED_DIR", str(REPO.parent / "shared")))
    if shared.is_dir():
        (root / "shared").symlink_to(shared)
    cli = os.environ.get("VMAP_CLI", "")
    if cli:
        (repo / "build" / "release" / "examples" / "vmap").symlink_to(cli)
    return repo


@pytest.mark.parametrize("page,kind,text", list(items()))
def test_documented_python_runs(page, kind, text, scratch, request):
    if "../shared" in text or "bench_python" in text:
        request.getfixturevalue("shared")  # skipped (or failed under CI) without ../shared
    if "bench_python" in text:
        request.getfixturevalue("vmap_cli")
    env = dict(os.environ, PYTHONPATH=str(pathlib.Path(vmap.__file__).resolve().parents[1]))
    if kind == "script":
        script = scratch / "snippet.py"
        script.write_text(text)
        argv = [sys.executable, str(script)]
    else:
        argv = [sys.executable] + shlex.split(text[len(PREFIX):])
    done = subprocess.run(argv, cwd=scratch, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{page}: exit {done.returncode}\n{text}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    assert done.stdout.strip(), f"{page}: printed nothing\n{text}"
