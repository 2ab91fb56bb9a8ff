"""A scene no solver setting was tuned for: a 60-degree normal fault bounding a sedimentary basin, drawdown in the
hanging wall (config/basin_fault.opts on a coarse mesh from benchmarks/basin_fault_mesh.py)."""

import os

import numpy as np
import pytest

from conftest import read_last_step, run, run_scene


@pytest.fixture(scope="module")
def basin(tmp_path_factory):
    d = tmp_path_factory.mktemp("basin")
    msh = str(d / "basin.msh")
    run([os.path.join("benchmarks", "basin_fault_mesh.py"), msh, "--size", "250"], timeout=300)
    out = {}
    for ranks in (1, 2):
        _, s = run_scene("config/basin_fault.opts", d / f"out{ranks}", ranks=ranks,
                         extra=["-pfault_mesh_file", msh])
        out[ranks] = (s, d / f"out{ranks}")
    return out


def test_every_step_converges_without_substeps(basin):
    """Full Newton steps from the scene's defaults: every step converges, none is cut, at most 15 iterations."""
    s, _ = basin[2]
    steps = [st for st in s["steps"] if st["time_s"] > 0]
    assert len(steps) == 10
    for st in steps:
        assert st["converged"] and st.get("substeps", 1) == 1, st
        assert st["newton_its"] <= 15, st
    assert steps[-1]["slip"] > 0                      # the fault slides


def test_hanging_wall_subsides_against_the_footwall(basin):
    """Normal-fault kinematics: the drained sediments pull the hanging wall down; the land surface steps down across
    the fault trace (x = 1200 m) by about the fault's dip slip times sin(60 degrees)."""
    s, out = basin[2]
    points, _, pd, _ = read_last_step(out)
    u = pd["displacement"]
    top = np.abs(points[:, 2]) < 1e-6
    x = points[:, 0]
    hanging = top & (x > 1300) & (x < 1600)
    foot = top & (x > 800) & (x < 1100)
    step = u[foot, 2].mean() - u[hanging, 2].mean()
    assert step > 0.5, step
    slip = s["max_fault_slip_m"]
    dip_throw = slip * np.sin(np.radians(60))        # measured: step 4.30 m, slip 5.03 m (throw 4.36 m)
    assert 0.8 * dip_throw < step < 1.1 * dip_throw, (step, slip)


def test_one_and_two_ranks_agree(basin):
    s1, _ = basin[1]
    s2, _ = basin[2]
    for key in ("max_fault_slip_m", "max_fault_opening_m", "max_subsidence_m"):
        assert s2[key] == pytest.approx(s1[key], rel=1e-6), key


@pytest.fixture(scope="module")
def basin_mesh(basin):
    return str(basin[1][1].parent / "basin.msh")


@pytest.mark.parametrize("method", ["lagrange", "penalty"])
def test_geostatic_state_is_in_equilibrium_on_an_inclined_fault(basin_mesh, tmp_path, method):
    """The K0 initial stress puts shear on the 60-degree fault (0.58 MPa on average). With a friction angle of 60
    degrees no face exceeds its Coulomb limit, and a step without drawdown must leave the state as it was: zero
    displacement, the same tractions. Both methods start their faces from the initial traction (penalty faces
    too: their shear starts from the initial one, not from zero), and the step converges though its load is
    zero (the gravity load scales its tolerance)."""
    import meshio
    out = tmp_path / method
    _, s = run_scene("config/basin_fault.opts", out, ranks=2,
                     extra=["-pfault_mesh_file", basin_mesh, "-pfault_fault_fault_method", method,
                            "-pfault_fault_fault_friction_angle", "60", "-pfault_time_steps", "1",
                            "-pfault_time_end", "1*year", "-pfault_material_basin_head_drawdown", "0:0,1*year:0",
                            "-pfault_time_max_cuts", "0"])
    assert s["converged"] and s["steps"][-1]["newton_its"] <= 2
    assert s["max_subsidence_m"] < 1e-12 and s["max_horizontal_displacement_m"] < 1e-12
    reader = meshio.xdmf.TimeSeriesReader(str(out / "fault.xdmf"))
    reader.read_points_cells()
    shear = [np.asarray(reader.read_data(k)[2]["traction_shear"][0]) for k in range(reader.num_steps)]
    mean = np.linalg.norm(shear[0], axis=1).mean()
    assert mean > 2e5, mean                          # the initial shear is there at step 0
    assert np.abs(shear[-1] - shear[0]).max() <= 1e-9 * np.abs(shear[0]).max()
    assert s["steps"][-1]["slip"] == 0 and s["steps"][-1]["open"] == 0
