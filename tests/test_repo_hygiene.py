"""Committed files carry no absolute path of the machine they were made on: results name their inputs relative to
their own folder, logs and data name no home or work directory.

Scans every text file git tracks (and untracked files git does not ignore, so a new file is checked before its first
commit). A machine path is a path under a user's or a build machine's directories (home folders, root's, a work
tree); scripts may still name scratch folders under the system's temp directory, which every machine has, but
results, data and documentation may not (they name where something was made, not where a script writes).
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
# a path segment at the start of an absolute path (not inside a URL or a longer path such as /var/...)
_START = r"(?<![\w.~$/-])/"
MACHINE = re.compile(_START + r"(?:" + "|".join(["work", "root", "home", "Users", "mnt", "scratch"]) + r")/")
TEMP = re.compile(_START + "tmp" + "/")
SCRIPTS = {".py", ".sh"}           # code that writes scratch files at run time may name the temp directory
SKIP_SUFFIXES = {".png", ".jpg", ".jpeg", ".gif", ".mp4", ".gsd", ".npz", ".whl", ".ico", ".pdf"}


def repo_text_files() -> list[Path]:
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git clone")
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                         capture_output=True, check=True).stdout.decode()
    files = []
    for name in sorted(set(filter(None, out.split("\0")))):
        p = REPO / name
        if p.suffix.lower() in SKIP_SUFFIXES or not p.is_file() or p.is_symlink():
            continue
        head = p.read_bytes()[:8192]
        if b"\0" in head:                # binary
            continue
        files.append(p)
    return files


def machine_paths(path: Path) -> list[str]:
    hits = []
    text = path.read_text(errors="replace")
    for i, line in enumerate(text.splitlines(), 1):
        if MACHINE.search(line) or (path.suffix not in SCRIPTS and TEMP.search(line)):
            hits.append(f"{path.relative_to(REPO)}:{i}: {line.strip()[:160]}")
    return hits


def test_the_patterns():
    bad = ["wrote " + "/" + "work/main/x.csv", 'path": "' + "/" + 'home/me/S3.gsd"', "(" + "/" + "root/.cache)",
           "in " + "/" + "tmp/x"]
    good = ["https://example.org/home/page", "/var/tmp/slurm", "~/.cache/taichi", "benchmarks/results/x.csv",
            "$OUT/work/x", "docs/home/x"]
    assert all(MACHINE.search(s) or TEMP.search(s) for s in bad)
    assert not any(MACHINE.search(s) or TEMP.search(s) for s in good)


def test_no_machine_paths_in_committed_files():
    hits = [h for p in repo_text_files() for h in machine_paths(p)]
    assert not hits, "absolute paths of the machine a file was made on (name them relative to the file's folder):\n" \
        + "\n".join(hits)
