"""The README's commands run as written, in order, on a fresh clone: every ```sh block of README.md, line by line.

The install prefix is checked, not run (this suite runs inside the environment it makes); the test command is
checked to be exactly the one CI runs (the last line of .ci/run); the docs command is checked to name an extra that
exists (CI builds the site). Every other line must be a `.venv/bin/python -m taichimyxo ...` command: it runs with this
interpreter from an empty folder, `scene` runs shortened with `--hours` (they keep `--preview`), and a command the
test does not know fails the test, so a new README command cannot go untested.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
INSTALL = "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && "
TEST_COMMAND = ".venv/bin/python -m pytest"
DOCS_COMMAND = ".venv/bin/pip install -e '.[docs]' && .venv/bin/mkdocs serve"
RUN = ".venv/bin/python -m taichimyxo "
SHORT_HOURS = "0.005"          # 18 simulated seconds: a frame at 0, 15 s and the end


def readme_commands() -> list[str]:
    text = (REPO / "README.md").read_text()
    blocks = re.findall(r"^```sh\n(.*?)^```", text, re.S | re.M)
    assert blocks, "README.md has no ```sh block"
    return [ln.strip() for b in blocks for ln in b.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def ci_test_command() -> str:
    lines = [ln.strip() for ln in (REPO / ".ci/run").read_text().splitlines()]
    return [ln for ln in lines if ln and not ln.startswith("#")][-1]


def test_readme_test_command_is_what_ci_runs():
    cmds = readme_commands()
    assert TEST_COMMAND in cmds
    assert ci_test_command() == TEST_COMMAND, "the last line of .ci/run must be the README's test command"
    assert cmds[0].startswith(INSTALL), "the README's first command installs and runs"
    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert "test" in extras and "docs" in extras


def test_readme_commands_run_in_order(tmp_path):
    env = dict(os.environ, TAICHIMYXO_THREADS="1")
    ran = []
    for cmd in readme_commands():
        if cmd.startswith(INSTALL):
            cmd = cmd[len(INSTALL):]
        if cmd in (TEST_COMMAND, DOCS_COMMAND):
            continue
        assert cmd.startswith(RUN), f"a README command this test does not know how to run: {cmd!r}"
        args = shlex.split(cmd[len(RUN):])
        if args[0] == "scene":
            assert "--hours" not in args
            args += ["--hours", SHORT_HOURS, "--quiet"]
        p = subprocess.run([sys.executable, "-m", "taichimyxo", *args], cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=900)
        assert p.returncode == 0, f"README command {cmd!r} failed:\n{p.stdout}\n{p.stderr}"
        ran.append((args, p.stdout + p.stderr))
    names = [a[:2] for a, _ in ran]
    assert ["scene", "S3"] in names and ["scene", "S8"] in names and ["analyze", "videos/S3-preview.gsd"] in names
    s8_output = next(out for a, out in ran if a[:2] == ["scene", "S8"])
    assert "rendered from trajectory S3-preview.gsd" in s8_output, s8_output   # S8 needs no second simulation
    videos = tmp_path / "videos"
    # every file the README's "What a run writes" table names was written
    table = re.search(r"^## What a run writes\n(.*?)^## ", (REPO / "README.md").read_text(), re.S | re.M).group(1)
    listed = re.findall(r"^\| `(S3-preview\.\w+)` \|", table, re.M)
    assert len(listed) == 4, listed
    for name in listed + ["S8-preview.png", "S3-preview.analysis.json"]:
        assert (videos / name).is_file() and (videos / name).stat().st_size > 0, name


def test_readme_is_short_and_its_links_resolve():
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= 200, "README.md is for a first-time user; details go to docs/"
    links = [m for m in re.findall(r"\]\(([^)\s]+)\)", text) if not re.match(r"\w+://", m)]
    assert "docs/usage.md" in links and "docs/tutorial.ipynb" in links
    for link in links:
        assert (REPO / link.split("#")[0]).exists(), f"README links {link}, which does not exist"
