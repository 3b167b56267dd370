"""The sweep file: a base scene, a grid of overrides by dotted key, seeds, duration, box size and outputs, expanded
into points, each a validated Scene (the file's format: taichimyxo/sweep/__init__.py).

Every point is resolved and validated here (Scene.load's checks, the step's stability limit, Taichi's field
indices) before any run starts; a bad file is refused with one line naming the key and the point (SweepError, a
SceneError, so the command line prints it as every other bad input and exits 2)."""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..io.scene import SCHEMA, Scene, SceneError, toml_value

TOP_KEYS = ("name", "description", "scene", "seeds", "hours", "scale", "box_um", "force")
TABLES = ("grid", "set", "outputs")
# executors' own tables ([slurm] ...): passed to the executor as its options, checked by it
EXECUTOR_TABLES = ("local", "slurm")
OUTPUT_KEYS = {"movie": (bool, False), "analysis_every": (int, 1), "analysis_plots": (bool, False)}


class SweepError(SceneError):
    """A sweep file that cannot run; the message is one line naming the key (and the point) at fault."""


@dataclass(frozen=True)
class Point:
    """One run of a sweep: the swept values, the seed and the resolved, validated scene."""
    name: str                      # readable: cell.k_a_N_m=1e-17_guiding.kind=active_seed=2
    overrides: dict                # swept dotted key -> value at this point
    seed: int
    scene: Scene

    @property
    def key(self) -> str:
        """Short hash of the resolved scene (every key but the names): a changed value is a new run."""
        return scene_key(self.scene)

    @property
    def dir_name(self) -> str:
        return f"{self.name}-{self.key}"

    def run_dir(self, root) -> Path:
        return Path(root) / "runs" / self.dir_name


@dataclass(frozen=True)
class Sweep:
    path: Path
    name: str
    base: str                      # the base scene: a name as `list` shows it, or a path
    grid: dict                     # dotted key -> list of values
    fixed: dict                    # dotted key -> value ([set])
    seeds: list
    hours: float | None
    scale: float | None
    box_um: tuple | None
    force: bool
    outputs: dict
    executor_options: dict = field(default_factory=dict)      # executor name -> its table
    description: str = ""
    grids: tuple = ()              # [[grid]] tables, each a product: their union (default: (grid,))

    @property
    def swept_keys(self) -> list[str]:
        return list(self.grid)

    def points(self) -> list[Point]:
        """Every combination of each grid's values with every seed, resolved and validated (SweepError at the first
        bad point). Points differing in a value are different runs even where the scene's fingerprint would not
        tell them apart (a duplicate combination within a grid is refused); a point of a later [[grid]] that
        resolves to the scene of an earlier one is that run, listed once (each decision's default, say)."""
        out, seen = [], {}
        bases: dict = {}
        for grid in self.grids or (self.grid,):
            mine: set = set()
            combos = itertools.product(*grid.values()) if grid else [()]
            for values in combos:
                over = dict(zip(grid, values))
                base_name = over.get("scene", self.base)
                if base_name not in bases:
                    bases[base_name] = self._base_scene(base_name)
                sized = self._sized(bases[base_name])
                for seed in self.seeds:
                    name = point_name(over, seed)
                    scene = self._resolve(base_name, sized, over, seed, name)
                    p = Point(name=name, overrides=over, seed=seed, scene=scene)
                    if p.key in mine:
                        raise SweepError(f"{self.path}: point {name} resolves to the same scene as {seen[p.key]}")
                    mine.add(p.key)
                    if p.key in seen:
                        continue
                    seen[p.key] = name
                    out.append(p)
        return out

    # ---- resolving a point
    def _base_scene(self, name: str) -> Scene:
        try:
            return Scene.load(name)
        except SceneError as e:
            raise SweepError(f"{self.path}: scene = {name!r}: {e}") from None

    def _sized(self, base: Scene) -> dict:
        """scale / box_um as overrides of the base scene: the box's sides, and an explicit cell count with the area
        (a density keeps itself), as --preview scales them."""
        if self.scale is None and self.box_um is None:
            return {}
        w0, h0 = base.box
        nested = base.resized(*((w0 * self.scale, h0 * self.scale) if self.scale is not None else self.box_um))
        return {f"{sec}.{k}": v for sec, body in nested.items() for k, v in body.items()}

    def _resolve(self, base: str, sized: dict, over: dict, seed: int, name: str) -> Scene:
        # later wins: the box's scaling, then [set], then the point's values, then seed and hours, so a value the
        # file gives is used as given, never scaled
        flat = {**sized, **self.fixed, **{k: v for k, v in over.items() if k != "scene"}, "run.seed": seed}
        if self.hours is not None:
            flat["run.hours"] = self.hours
        flat["output.movie"] = self.outputs["movie"]
        flat["scene.name"] = name
        flat["scene.title"] = f"{self.name}: {name}"
        nested: dict = {}
        for key, val in flat.items():
            sec, k = key.split(".")
            nested.setdefault(sec, {})[k] = val
        try:
            scene = Scene.load(base, nested)
            from ..physics.stability import check_step
            check_step(scene, force=self.force)
            from ..runtime.resources import check_resources
            check_resources(scene, available=2 ** 62)      # Taichi's indices; memory is the executing machine's
        except SceneError as e:
            msg = str(e).replace("--set: ", "")
            raise SweepError(f"{self.path}: point {name}: {msg}") from None
        return scene


def scene_key(scene: Scene, length: int = 10) -> str:
    """Hash of the resolved scene's values, names and title left out (the point's name is in the run's folder)."""
    d = scene.trajectory_values(exclude=("scene", "preview"))
    d["_dt"] = scene.dt
    return hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:length]


def choose_runs(names: list[str], patterns: list[str] | None, flag: str) -> set | None:
    """The run names that `--runs` shell patterns match (None: no patterns, every run); a pattern matching none is
    refused (SweepError naming the flag and a few of the names)."""
    from fnmatch import fnmatchcase
    if not patterns:
        return None
    known = sorted(set(names))
    for pat in patterns:
        if not any(fnmatchcase(n, pat) for n in known):
            raise SweepError(f"{flag} --runs {pat!r}: matches none of the runs ({', '.join(known[:4])}"
                             f"{', ...' if len(known) > 4 else ''})")
    return {n for n in known if any(fnmatchcase(n, pat) for pat in patterns)}


def value_text(v) -> str:
    """A value as it reads in a point's name: 1e-17, active, true, 0.5."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def point_name(over: dict, seed: int) -> str:
    parts = [f"{k}={value_text(v)}" for k, v in over.items()] + [f"seed={seed}"]
    # a folder name: nothing a path or a shell would read otherwise
    return re.sub(r"[^A-Za-z0-9._=+-]", "-", "_".join(parts))


# ------------------------------------------------------------------------------------------------ the file
def _flatten(table: dict, where: str, path: Path) -> dict:
    """{"cell": {"k_a_N_m": [...]}} (TOML dotted keys) or {"cell.k_a_N_m": [...]} (quoted) -> dotted keys, each a
    scene key."""
    out = {}
    for k, v in table.items():
        if isinstance(v, dict):
            for k2, v2 in v.items():
                if isinstance(v2, dict):
                    raise SweepError(f"{path}: [{where}] {k}.{k2}: expected SECTION.KEY, e.g. cell.k_a_N_m")
                out[f"{k}.{k2}"] = v2
        else:
            out[k] = v
    for key in out:
        if key == "scene" and where == "grid":
            continue                        # base scenes, checked by load_sweep
        sec, _, k = key.partition(".")
        if sec not in SCHEMA or k not in SCHEMA[sec]:
            raise SweepError(f"{path}: [{where}] {key}: unknown key; see `python -m taichimyxo keys`")
        if key == "run.seed":
            raise SweepError(f"{path}: [{where}] run.seed: give the seeds with `seeds = N` or `seeds = [...]`")
        if key in ("scene.name", "scene.title"):
            raise SweepError(f"{path}: [{where}] {key}: a sweep names its runs after their points")
        if key == "output.movie":
            raise SweepError(f"{path}: [{where}] output.movie: say it once for every run, in [outputs] movie")
    return out


def _number(data: dict, key: str, path: Path, positive: bool = True):
    v = data.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        raise SweepError(f"{path}: {key} = {v!r}: expected a positive number")
    return float(v)


def _seeds(data: dict, path: Path, base_seed) -> list[int]:
    s = data.get("seeds")
    if s is None:
        return [base_seed]
    if isinstance(s, int) and not isinstance(s, bool):
        if s < 1:
            raise SweepError(f"{path}: seeds = {s}: give a count of at least 1, or a list of seeds")
        return list(range(1, s + 1))
    if isinstance(s, list):
        if not s:
            raise SweepError(f"{path}: seeds = []: give at least one seed")
        if any(isinstance(x, bool) or not isinstance(x, int) or x < 0 for x in s):
            raise SweepError(f"{path}: seeds = {s!r}: seeds are integers >= 0")
        if len(set(s)) != len(s):
            raise SweepError(f"{path}: seeds = {s!r}: a seed appears twice")
        return list(s)
    raise SweepError(f"{path}: seeds = {s!r}: expected a count (3: seeds 1, 2, 3) or a list ([1, 7, 42])")


def _outputs(table, path: Path) -> dict:
    if not isinstance(table, dict):
        raise SweepError(f"{path}: [outputs] must be a table")
    out = {k: d for k, (_, d) in OUTPUT_KEYS.items()}
    for k, v in table.items():
        if k not in OUTPUT_KEYS:
            raise SweepError(f"{path}: [outputs] {k}: unknown key; allowed: {', '.join(OUTPUT_KEYS)} (the "
                             f"trajectory, summary and analysis are always written)")
        typ = OUTPUT_KEYS[k][0]
        if not isinstance(v, typ) or (typ is int and (isinstance(v, bool) or v < 1)):
            raise SweepError(f"{path}: [outputs] {k} = {toml_value(v)}: expected "
                             f"{'true or false' if typ is bool else 'an integer >= 1'}")
        out[k] = v
    return out


def _scene_path(base: str, path: Path) -> str:
    """A scene as a sweep file names it: a name as `list` shows it, or a .toml path relative to the file."""
    if base.endswith(".toml") or "/" in base:
        return str((path.parent / base).resolve()) if not Path(base).is_absolute() else base
    return base


def load_sweep(path) -> Sweep:
    """Read and check a sweep file (its format: taichimyxo/sweep/__init__.py). The points are resolved and validated
    by Sweep.points()."""
    from ..io.catalogue import resolve_sweep
    path = resolve_sweep(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise SweepError(f"sweep file {path} not found") from None
    except OSError as e:
        raise SweepError(f"sweep file {path}: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise SweepError(f"{path}: malformed TOML: {e}") from None
    for k, v in data.items():
        if k == "grid" and isinstance(v, list):
            if not v or not all(isinstance(g, dict) for g in v):
                raise SweepError(f"{path}: [[grid]] must be one or more tables")
        elif k in TABLES or k in EXECUTOR_TABLES:
            if not isinstance(v, dict):
                raise SweepError(f"{path}: [{k}] must be a table")
        elif k not in TOP_KEYS:
            raise SweepError(f"{path}: unknown key {k!r}; allowed: {', '.join(TOP_KEYS)} and the tables "
                             f"[{'], ['.join(TABLES + EXECUTOR_TABLES)}]")
    tables = data.get("grid", {})
    grids = [_flatten(t, "grid", path) for t in (tables if isinstance(tables, list) else [tables])]
    for grid in grids:
        if "scene" in grid:
            scenes = grid["scene"]
            if not isinstance(scenes, list) or not scenes or not all(isinstance(x, str) for x in scenes):
                raise SweepError(f"{path}: [grid] scene = {toml_value(scenes)}: expected a list of scene names, e.g. "
                                 f"[\"S1\", \"S3\"]")
            grid["scene"] = [_scene_path(x, path) for x in scenes]
            if "scene" in data:
                raise SweepError(f"{path}: scene and [grid] scene both given; keep one")
    named = [g for g in grids if "scene" in g]
    if named:
        if len(named) < len(grids):
            raise SweepError(f"{path}: [[grid]]: some grids name their scenes and some do not; give each its "
                             f"scene = [...]")
        data = {**data, "scene": named[0]["scene"][0]}
    if "scene" not in data or not isinstance(data["scene"], str):
        raise SweepError(f"{path}: scene: name the base scene, e.g. scene = \"S1\" (a name as `list` shows it, or "
                         f"a .toml path relative to the sweep file), or several in [grid] scene = [...]")
    base = _scene_path(data["scene"], path)
    for grid in grids:
        for key, vals in grid.items():
            if not isinstance(vals, list):
                raise SweepError(f"{path}: [grid] {key} = {toml_value(vals)}: expected a list of values (a fixed "
                                 f"value goes in [set])")
            if not vals:
                raise SweepError(f"{path}: [grid] {key} = []: an empty list gives no points; give at least one "
                                 f"value")
    grid: dict = {}                 # every swept key with every value it takes, in the order the file gives them
    for g in grids:
        for key, vals in g.items():
            grid.setdefault(key, [])
            grid[key] += [v for v in vals if v not in grid[key]]
    fixed = _flatten(data.get("set", {}), "set", path)
    for key in set(grid) & set(fixed):
        raise SweepError(f"{path}: {key} is both in [grid] and in [set]")
    hours = _number(data, "hours", path)
    if hours is not None and ("run.hours" in grid or "run.hours" in fixed):
        raise SweepError(f"{path}: hours and run.hours both given; keep one")
    scale = _number(data, "scale", path)
    box = data.get("box_um")
    if box is not None:
        if scale is not None:
            raise SweepError(f"{path}: scale and box_um both given; keep one")
        if not (isinstance(box, list) and len(box) == 2 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and x > 0 for x in box)):
            raise SweepError(f"{path}: box_um = {box!r}: expected [width, height] in µm, e.g. [100, 100]")
        box = (float(box[0]), float(box[1]))
        sized = {"domain.width_um", "domain.height_um"} & (set(grid) | set(fixed))
        if sized:
            raise SweepError(f"{path}: box_um and {sorted(sized)[0]} both given; keep one")
    force = data.get("force", False)
    if not isinstance(force, bool):
        raise SweepError(f"{path}: force = {force!r}: expected true or false")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9._+-]+", name):
        raise SweepError(f"{path}: name = {name!r}: letters, digits and . _ + - only (it names files)")
    seeds_of = {}
    for b in {b: None for g in grids for b in g.get("scene", [base])}:
        try:
            seeds_of[b] = Scene.load(b).seed
        except SceneError as e:
            raise SweepError(f"{path}: scene = {b!r}: {e}") from None
    base_seed = seeds_of[base]
    return Sweep(path=path, name=name, base=base, grid=grid, fixed=fixed, seeds=_seeds(data, path, base_seed),
                 hours=hours, scale=scale, box_um=box, force=force, outputs=_outputs(data.get("outputs", {}), path),
                 executor_options={k: dict(data[k]) for k in EXECUTOR_TABLES if k in data},
                 description=str(data.get("description", "")), grids=tuple(grids) if len(grids) > 1 else ())
