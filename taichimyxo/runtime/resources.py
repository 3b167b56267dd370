"""What a run will need, checked before anything is placed or allocated.

A scene that validates can still be far too large for the machine (a 10^6 µm domain at the paper's density holds
5 x 10^10 cells): without this check numpy or Taichi dies minutes later with a traceback ('Unable to allocate
5.82 TiB'). `check_resources(scene)` estimates the memory of every field a Simulation allocates (the same sizes
as the Simulation's parts, tested against Simulation.allocated_fields), of the start's placement and of the per-frame
copies, and
refuses the run with one line when it exceeds the memory available, or when a field would have more entries than
Taichi's 32-bit field indices address."""
from __future__ import annotations

import os

from ..io.scene import SceneError

GiB = 1024 ** 3
# the interpreter, numpy, the Taichi runtime, LLVM and compiled kernels, whatever the scene's size (measured: a
# 20 x 20 µm S3 peaks at ~390 MiB resident on the CPU)
RUNTIME_BYTES = 512 * 1024 ** 2
# per particle, host copies made while running: placement (positions, their shifted copy, the copy handed to
# Taichi), and each frame (the field read back, the unwrapped chains, the trajectory's wrapped positions and images)
HOST_BYTES_PER_PARTICLE = 8 * 2 * 8
INDEX_LIMIT = 2 ** 31 - 1          # Taichi indexes fields with 32-bit integers
# what a field holds, for messages
FIELD_NAMES = {"nbr": "the neighbour list", "rev": "the neighbour list", "pair_f": "the contact pairs' forces",
               "guide": "the guiding list", "bin_count": "the neighbour-search grid",
               "bin_start": "the neighbour-search grid", "bin_cursor": "the neighbour-search grid",
               "slime": "the slime grid", "slime_claim": "the slime grid", "Lf": "the implicit step's factors",
               "ct_t": "the implicit step's contact list", "ct_w": "the implicit step's contact list"}


def _fmt(n: float) -> str:
    for unit, size in (("TiB", 1024 ** 4), ("GiB", GiB), ("MiB", 1024 ** 2)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n / 1024:.3g} KiB"


def field_sizes(scene, contacts: str | None = None) -> dict:
    """Name -> (entries, bytes) of every field the scene's Simulation allocates (state.py, neighbours.py, the units
    of terms/ and the integrator), by the same rules; contacts: the imex option (default: the scene's)."""
    from ..physics.neighbours import grid_radius
    from ..physics.state import list_capacities
    from .launch import shape_for
    imex = scene.integrator in ("imex", "imex-explicit")
    contacts = contacts or ("explicit" if scene.integrator == "imex-explicit" else "coupled")
    n, N = scene.n_cells, scene.N
    P, S, C = n * N, n * (N - 1), n
    pb = 8 if scene.precision in ("f64", "mixed") else 4         # positions
    force_bytes = 8 if scene.precision == "f64" else 4                     # forces
    caps = list_capacities(scene)
    cap = caps["capacity"]
    cutoff = scene.width + scene.skin + caps.get("guiding_range", 0.0)
    r = grid_radius(scene.rest_length, cutoff)
    Lx, Ly = scene.box
    bins = max(1, int(Lx // r)) * max(1, int(Ly // r))
    out = {"x": (P, P * 2 * pb), "x_ref": (P, P * 2 * pb), "x_snap": (P, P * 2 * pb), "ke": (C, C * 4),
           "nbr": (S * cap, S * cap * 4), "rev": (S * cap, S * cap * 4), "nbr_n": (S, S * 4),
           "bin_count": (bins, bins * 4), "bin_start": (bins + 1, (bins + 1) * 4), "bin_cursor": (bins, bins * 4),
           "bin_items": (S, S * 4), "bin_geo": (S, S * 3 * force_bytes), "seg_bin": (S, S * 4), "flags": (4, 16)}
    if "guiding_capacity" in caps:
        g = 2 * C * caps["guiding_capacity"]
        out["guide"] = (g, g * 4)
        out["guide_n"] = (2 * C, 2 * C * 4)
    if imex and contacts != "explicit":
        out["fa"] = (S, S * 2 * force_bytes)                                # each segment gathers and records its own
        out["fb"] = (S, S * 2 * force_bytes)
    else:
        out["pair_f"] = (S * cap, S * cap * 8 * force_bytes)                # each pair once, both sides' results
    if scene.guiding != "none":
        out["g_head"] = (C, C * 2 * force_bytes)
    if scene.guiding == "adhesion":
        out["g_tail"] = (C, C * 2 * force_bytes)
    if scene.suppression:
        out["interacting"] = (C, C * 2 * 4)
    if scene.guiding != "none" or scene.suppression:
        out["leader"] = (C, C * 4)                                  # who each head follows (the event log)
    if scene.reversals:
        for k in ("rev_clock", "rev_period", "rev_count", "rev_suppressed"):
            out[k] = (C, C * 4)
        out["clock_held"] = (1, 4)
    if scene.slime:
        g = max(1, int(round(Lx / scene.slime_grid))) * max(1, int(round(Ly / scene.slime_grid)))
        out["slime"] = (g, g * 2 * 4)
        out["slime_claim"] = (g, g * 4)
    if scene.strain:
        out["strain_seg"] = (S, S * 8)
    if scene.mass > 0 and not imex:
        out["v"] = (P, P * 2 * force_bytes)
    if imex:
        from ..physics.terms.contacts import Contacts
        bw = min(6, 2 * N)
        out["Lf"] = (2 * P * (bw + 1), 2 * P * (bw + 1) * force_bytes)
        for k in ("vel", "rhs", "tmp"):
            out[k] = (2 * P, 2 * P * force_bytes)
        out["tan"] = (P, P * 2 * force_bytes)
        out["xrel"] = (P, P * 2 * force_bytes)
        if contacts != "explicit":
            m = Contacts.MAX_CONTACTS
            out["ct_n"] = (S, S * 4)
            out["ct_t"] = (S * m, S * m * 4)
            out["ct_w"] = (S * m, S * m * 4 * force_bytes)
            out["overflow"] = (1, 4)
        if contacts == "coupled":
            for k in ("cg_r", "cg_u", "cg_w", "cg_p", "cg_s", "vprev"):
                out[k] = (2 * P, 2 * P * force_bytes)
            out["active"] = (C, C * 4)
            nblk = shape_for(S, "cpu").cell_blocks(C)        # the CPU's (a GPU's fields are on the device)
            out["part"] = (nblk * 3, nblk * 3 * 8)
        out["cgs"] = (8, 64)
        out["cgi"] = (8, 32)
    return out


def estimate(scene) -> dict:
    """Bytes by part: 'fields' (Taichi), 'neighbour_list' (its share of the fields), 'slime_grid' (likewise),
    'host' (numpy copies), 'runtime', 'total'."""
    f = field_sizes(scene)
    fields = sum(b for _, b in f.values())
    P = scene.n_cells * scene.N
    host = P * HOST_BYTES_PER_PARTICLE
    if scene.start == "random":
        from ..physics.placement import placement_grid_bytes
        host += placement_grid_bytes(scene)
    lists = f["nbr"][1] + f["rev"][1] + f.get("pair_f", (0, 0))[1] + f.get("guide", (0, 0))[1] + f["bin_count"][1] * 3
    return {"fields": fields, "neighbour_list": lists,
            "slime_grid": f["slime"][1] + f["slime_claim"][1] if "slime" in f else 0,
            "host": host, "runtime": RUNTIME_BYTES, "total": fields + host + RUNTIME_BYTES, "_sizes": f}


def available_memory() -> int | None:
    """Bytes this process can still allocate: MemAvailable, lowered to a cgroup's limit where one is set.
    None where neither can be read (the check is then skipped)."""
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except OSError:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = None
    for lim_path, cur_path in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                               ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(lim_path) as fh:
                lim = fh.read().strip()
            with open(cur_path) as fh:
                cur = int(fh.read().strip())
        except (OSError, ValueError):
            continue
        if lim.isdigit() and int(lim) < 2 ** 60:
            room = int(lim) - cur
            avail = room if avail is None else min(avail, room)
        break
    return avail


def check_resources(scene, available: int | None = None) -> dict:
    """Refuse (SceneError, one line) a scene whose fields Taichi cannot index or whose memory exceeds what is
    available. Returns the estimate."""
    est = estimate(scene)
    Lx, Ly = scene.box
    what = f"{scene.n_cells} cells in {Lx:g} x {Ly:g} µm"
    fix = "reduce domain.width_um x domain.height_um or the population"
    big, (entries, _) = max(est["_sizes"].items(), key=lambda kv: kv[1][0])
    if entries > INDEX_LIMIT:
        raise SceneError(f"{what} need about {_fmt(est['total'])} of memory, and {FIELD_NAMES.get(big, big)} "
                         f"would hold {entries:.3g} entries, more than the 2^31 Taichi can index; {fix}"
                         f"{scene.preview_note()}")
    avail = available_memory() if available is None else available
    if avail is not None and est["total"] > avail:
        parts = [f"neighbour list {_fmt(est['neighbour_list'])}"]
        if est["slime_grid"]:
            parts.append(f"slime grid {_fmt(est['slime_grid'])}")
        parts.append(f"other fields {_fmt(est['fields'] - est['neighbour_list'] - est['slime_grid'])}")
        parts.append(f"positions and frames {_fmt(est['host'])}")
        raise SceneError(f"{what} need about {_fmt(est['total'])} of memory ({', '.join(parts)}); this machine "
                         f"has {_fmt(avail)} available; {fix}{scene.preview_note()}")
    return est
