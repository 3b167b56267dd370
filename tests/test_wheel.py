"""The install: the package laid out as pyproject.toml tells setuptools to build the wheel (package-dir,
package-data), and run from outside the clone, finds its scenes and the stability limits it ships
(stability_limits.json), so `list` shows every scene and the step limits are the shipped ones."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

from taichimyxo.io.scene import available_scenes

REPO = Path(__file__).resolve().parent.parent


def test_the_wheel_layout_has_the_scenes_and_the_limits(tmp_path):
    """Lay the package out as pyproject.toml tells setuptools to (package-dir, package-data) and run it from
    outside the clone: `list` shows every scene, and the step limits come from the shipped stability_limits.json."""
    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    site = tmp_path / "site"
    for pkg in conf["packages"]:
        src = REPO / conf["package-dir"][pkg]
        dst = site / pkg.replace(".", "/")
        dst.mkdir(parents=True)
        patterns = ["*.py"] + conf.get("package-data", {}).get(pkg, [])
        for pat in patterns:
            for f in src.glob(pat):
                shutil.copy(f, dst / f.name)
    assert (site / "taichimyxo/physics/stability_limits.json").is_file()
    env = dict(os.environ, PYTHONPATH=str(site))
    code = ("import taichimyxo, taichimyxo.io.scene as s, taichimyxo.physics.stability as st; "
            "print(taichimyxo.__file__); "
            "print(s.SCENES_DIR); print(st._LIMITS_FILE.is_file())")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                       timeout=600)
    assert p.returncode == 0, p.stderr
    file_, scenes_dir, limits = p.stdout.split()
    assert file_.startswith(str(site)) and scenes_dir == str(site / "taichimyxo" / "scenes") and limits == "True"
    p = subprocess.run([sys.executable, "-m", "taichimyxo", "list"], capture_output=True, text=True, cwd=tmp_path,
                       env=env, timeout=600)
    assert p.returncode == 0, p.stderr
    assert [ln.split()[0] for ln in p.stdout.splitlines()] == available_scenes()
