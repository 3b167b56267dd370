"""Helpers for building small simulations in tests."""
import math

import numpy as np

from taichimyxo import backend
from taichimyxo import geometry
from taichimyxo.init import straight_cell
from taichimyxo.scene import Scene

backend.init("cpu", default_fp="f64")      # f64 constants, so f64 scenes are exact to ~1e-12


def scene(box=(20.0, 20.0), cells=2, **sections):
    d = {"domain": {"width_um": float(box[0]), "height_um": float(box[1])},
         "population": {"cells": cells}, "output": {"movie": False}}
    for sec, body in sections.items():
        d.setdefault(sec, {}).update(body)
    return Scene.from_dict(d)


def sim_with(positions, ke=None, box=(20.0, 20.0), **sections):
    from taichimyxo.sim import make_simulation
    pos = np.asarray(positions, float)
    if pos.ndim == 2:
        pos = pos[None]
    ke = np.ones(len(pos), int) if ke is None else np.asarray(ke)
    sc = scene(box=box, cells=len(pos), **sections)
    return make_simulation(sc, positions=pos, engine_direction=ke)


def cell(centre, angle_deg=0.0, N=8, l0=4.5 / 7):
    return straight_cell(np.asarray(centre, float), math.radians(angle_deg), N, l0)


def arc_cell(centre, radius, start_deg, N=8, l0=4.5 / 7, direction=1):
    """Particles on a circle of `radius`, consecutive particles l0 apart (chord)."""
    dth = 2 * math.asin(l0 / (2 * radius)) * direction
    th = math.radians(start_deg) + dth * np.arange(N)
    return np.stack([centre[0] + radius * np.cos(th), centre[1] + radius * np.sin(th)], axis=1)


# ---------------------------------------------------------------- numpy reference energies (docs/model.md terms 1, 2, 4)
def spring_energy(pos, k_s, l0):
    l = np.linalg.norm(np.diff(pos, axis=-2), axis=-1)
    return 0.5 * k_s * np.sum((l - l0) ** 2)


def bend_energy(pos, k_a):
    d = np.diff(pos, axis=-2)
    a, b = d[..., :-1, :], d[..., 1:, :]
    th = np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], np.sum(a * b, -1))
    return 0.5 * k_a * np.sum(th ** 2)


def contact_energy(pos, box, W, k_c):
    """The contact energy from its definition (node to nearest point of each other chain), numpy: see
    taichimyxo.geometry.contact_energy. Written without the kernels' local nearest-segment rule."""
    return geometry.contact_energy(pos, box, W, k_c)


def fd_gradient(fun, pos, h=1e-6):
    g = np.zeros_like(pos)
    it = np.nditer(pos, flags=["multi_index"])
    for _ in it:
        i = it.multi_index
        p = pos.copy()
        p[i] += h
        ep = fun(p)
        p[i] -= 2 * h
        em = fun(p)
        g[i] = (ep - em) / (2 * h)
    return g
