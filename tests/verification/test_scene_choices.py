"""Choices a scene makes about its initial stress and about where its pore-pressure change loads the skeleton.

- -pfault_geostatic_stress lithostatic: in a column of three layers (1800, 2000, 2400 kg/m^3, 10 m each, rollers on
  the sides) the initial vertical stress of every cell is the weight of the column above its centroid, -int rho g dz
  (to round-off), the horizontal ones the K0 rule, the same on 1 and 2 ranks; the default elastic gravity solve gives
  another stress (its cells' vertical stress is the mean over a tetrahedron's height, not the value at its
  centroid).
- -pfault_pore_pressure_unchanged_materials: a box of clay over sand drained by a well (the flow model): the clay's
  cells have no pore-pressure change in fields.h5, the sand's and the head the same as without the option (the
  flow model is unchanged), less subsidence; the effects line and summary.json say it; a restart from its first
  step's checkpoint (the flow model's head) gives the same run.
"""

import h5py
import numpy as np
import pytest

from conftest import FLOW_BOX, compare_runs, run_scene

G = 9.80665
LAYERS = ((0.0, 10.0, 1800.0, 0.3), (10.0, 20.0, 2000.0, 0.25), (20.0, 30.0, 2400.0, 0.2))   # depths, rho, nu
COLUMN = """# three layers in a column held laterally by rollers, a geostatic start and nothing else
-pfault_mesh_generator box
-pfault_box_size 10,10,30
-pfault_box_cells 1,1,6
-pfault_box_materials top,mid,bot
-pfault_box_interfaces 10,20
""" + "".join(f"-pfault_material_{name}_young_modulus {e}*MPa\n-pfault_material_{name}_poisson_ratio {nu}\n"
              f"-pfault_material_{name}_density {rho}\n"
              for name, e, (_, _, rho, nu) in zip(("top", "mid", "bot"), (10, 20, 50), LAYERS)) + """
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_bc_bottom_type fixed
-pfault_geostatic true
-pfault_time_end 1
-pfault_time_steps 1
-pfault_solver mumps
"""


def initial_stress(out):
    """Cell centroids and the stress (n x 3 x 3) of step 0 in fields.h5."""
    with h5py.File(out / "fields.h5", "r") as f:
        x = f["mesh/points"][()][f["mesh/cells"][()]]
        return x.mean(axis=1), f["steps/000000/stress"][()].reshape(-1, 3, 3), f["steps/000000/material"][()]


@pytest.fixture(scope="module")
def column(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("column")
    scene = tmp / "column.opts"
    scene.write_text(COLUMN)
    runs = {}
    for name, ranks, extra in (("gravity", 1, []), ("lithostatic", 1, ["-pfault_geostatic_stress", "lithostatic"]),
                               ("lithostatic2", 2, ["-pfault_geostatic_stress", "lithostatic"])):
        proc, summary = run_scene(str(scene), tmp / name, ranks=ranks, extra=extra)
        runs[name] = (proc, summary, initial_stress(tmp / name))
    return runs


def test_lithostatic_stress_is_the_weight_of_the_column(column):
    _, summary, (c, s, material) = column["lithostatic"]
    depth = -c[:, 2]
    weight = G * sum(rho * np.clip(depth - a, 0.0, b - a) for a, b, rho, _ in LAYERS)
    assert np.abs(s[:, 2, 2] + weight).max() <= 1e-12 * weight.max()
    nu = np.array([nu for *_, nu in LAYERS])[material]
    p0 = 1000.0 * G * depth                     # hydrostatic below the water table at the land surface
    sh = nu / (1 - nu) * (s[:, 2, 2] + p0) - p0
    assert np.allclose(s[:, 0, 0], sh, rtol=1e-12, atol=0) and np.array_equal(s[:, 0, 0], s[:, 1, 1])
    assert summary["effects"]["geostatic"]["detail"].startswith("lithostatic initial stress")
    _, _, (_, s2, _) = column["lithostatic2"]
    assert np.allclose(s2, s, rtol=1e-14, atol=1e-14 * weight.max())


def test_the_default_is_the_gravity_solve(column):
    proc, summary, (_, s, _) = column["gravity"]
    _, _, (_, litho, _) = column["lithostatic"]
    assert "geostatic start gravity solve, K0 initial stress" in proc.stdout
    assert summary["effects"]["geostatic"]["detail"] == "gravity solve, K0 initial stress"
    difference = np.abs(s[:, 2, 2] - litho[:, 2, 2])
    assert difference.max() > 0.01 * np.abs(litho[:, 2, 2]).max()
    # the same column in total: the gravity solve's mean vertical stress over the column, weighted by the cells'
    # heights, is the lithostatic one's at the same cells to the discretisation (here within 4 %)
    assert np.mean(s[:, 2, 2]) == pytest.approx(np.mean(litho[:, 2, 2]), rel=0.04)


CLAY_OVER_SAND = FLOW_BOX.replace("-pfault_material_soil_", "-pfault_material_sand_").replace(
    "-pfault_box_cells 2,2,2", "-pfault_box_cells 2,2,4") + """
-pfault_box_materials clay,sand
-pfault_box_interfaces 10
-pfault_material_clay_young_modulus 5*MPa
-pfault_material_clay_poisson_ratio 0.3
-pfault_material_clay_hydraulic_conductivity 0.01*m/day
-pfault_time_end 2*day
-pfault_time_steps 2
"""


def cell_values(out, key, step="000002"):
    with h5py.File(out / "fields.h5", "r") as f:
        return f[f"steps/{step}/{key}"][()], f[f"steps/{step}/material"][()]


def test_a_material_whose_pore_pressure_does_not_change(tmp_path):
    scene = tmp_path / "clay_over_sand.opts"
    scene.write_text(CLAY_OVER_SAND)
    _, free = run_scene(str(scene), tmp_path / "free")
    proc, held = run_scene(str(scene), tmp_path / "held", extra=["-pfault_pore_pressure_unchanged_materials",
                                                                 "clay"])
    dp_free, material = cell_values(tmp_path / "free", "pore_pressure_change")
    dp_held, _ = cell_values(tmp_path / "held", "pore_pressure_change")
    clay = material == 0
    assert clay.any() and (~clay).any()
    assert np.all(dp_held[clay] == 0.0) and np.all(dp_free[clay] < -1.0)      # the well drains the clay too
    assert np.array_equal(dp_held[~clay], dp_free[~clay])
    head_free, head_held = (cell_values(tmp_path / run, "head_change")[0] for run in ("free", "held"))
    assert np.array_equal(head_held, head_free) and head_free.min() < -0.1
    assert 0 < held["max_subsidence_m"] < free["max_subsidence_m"]
    line = "groundwater flow transient groundwater flow (pore pressure unchanged in clay)"
    assert line in proc.stdout and held["effects"]["flow"]["detail"] == line.removeprefix("groundwater flow ")
    assert free["effects"]["flow"]["detail"] == "transient groundwater flow"
    held_opts = ["-pfault_pore_pressure_unchanged_materials", "clay"]
    run_scene(str(scene), tmp_path / "part", extra=[*held_opts, "-pfault_time_end", "1*day", "-pfault_time_steps", "1"])
    _, again = run_scene(str(scene), tmp_path / "part", extra=[*held_opts, "-pfault_restart", str(tmp_path / "part")])
    assert again["completed_steps"] == [1, 2]
    compare_runs(tmp_path / "held", tmp_path / "part", 1e-12)
