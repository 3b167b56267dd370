"""Memory: a domain too large for this machine, or for Taichi's indices, is refused in one line before anything is
allocated or written; taichimyxo.runtime.resources' estimate names its parts (fields, neighbour list, slime grid) and
compares their sum with the memory available; and the field sizes it estimates are exactly what a Simulation allocates,
for every combination of effects, integrator, mass and precision."""
from __future__ import annotations

import pytest

from simtools import build_small_scene, cli, error_line
from taichimyxo.io.scene import SceneError


def test_a_domain_beyond_memory_is_refused_in_one_line(tmp_path):
    """The issue's 10^6 µm domain (5 x 10^10 cells) died in numpy ('Unable to allocate 5.82 TiB')."""
    line = error_line(cli("scene", "S1", "--no-movie", "--out", tmp_path / "o", "--set", "domain.width_um=1e6",
                          "--set", "domain.height_um=1e6"))
    assert "50000000000 cells in 1e+06 x 1e+06 µm" in line
    assert "Taichi can index" in line or "need about" in line
    assert not (tmp_path / "o").exists()


def test_memory_estimate_names_the_parts_and_compares_with_what_is_available():
    from taichimyxo.runtime.resources import check_resources, estimate
    sc = build_small_scene(0, box=(2000.0, 2000.0), slime={"enabled": True})
    est = estimate(sc)
    assert est["total"] > est["fields"] > est["neighbour_list"] > 0 and est["slime_grid"] > 0
    with pytest.raises(SceneError, match=r"need about .* \(neighbour list .*, slime grid .*\); this machine has "
                                         r"1 GiB available"):
        check_resources(sc, available=1024 ** 3)
    assert check_resources(sc, available=10 * est["total"])["total"] == est["total"]


@pytest.mark.parametrize("over", [
    {},
    {"guiding": {"kind": "adhesion"}, "output": {"strain": True}},
    {"reversals": {"enabled": True, "suppression": True}, "guiding": {"kind": "active"}, "slime": {"enabled": True}},
    {"run": {"integrator": "imex", "precision": "f64"}, "guiding": {"kind": "passive"}},
    {"run": {"mass_pg": 1.0, "precision": "f32"}},
], ids=["plain", "adhesion-strain", "reversals-slime", "imex", "mass-f32"])
def test_field_estimate_matches_what_the_simulation_allocates(make_sim, over):
    from taichimyxo.runtime.resources import field_sizes
    sc = build_small_scene(4, **over)
    sim = make_sim(sc)
    allocated = sim.allocated_fields()
    estimated = {k: b for k, (_, b) in field_sizes(sc).items()}
    assert estimated == allocated
