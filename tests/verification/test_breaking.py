"""Candidate surfaces that break (pfault.faults.breaking): a face is glued until its traction leaves its intact
strength surface, then broken for good with the residual cohesion.

- A bar pulled apart across a candidate plane (uniaxial stress s = E u / L, tensile strength T): stretched to
  1 - 1e-8 of the breaking stretch every face is intact, closed and without jump (to round-off); at 1 + 1e-8 every
  face is broken (in the step's passes), open by the whole stretch and traction-free; on 1 and 2 ranks.
- Two blocks pressed together and sheared in proportion (uniform state: shear tau = s tau0, pressure s p0): intact
  up to s* = c / (tau0 - p0 tan(phi)) (to 1e-8), then broken on the residual cohesion: |t_T| = c_r - t_N tan(phi)
  on the slipping faces, the apex c_r / tan(phi) on those the blocks' rotation opens; on 1 and 2 ranks.
- The fissure box (config/hard/fissure_box.opts, clay over sand over rock, drawdown in the sand; 12.5 m x 12.5 m x
  5 m hexahedra) with a candidate plane x = 387.5 m from the land surface to 60 m depth, T = 15 kPa, c = 1 MPa (so
  that it breaks in tension): the bending over the basin margin pulls the clay apart. The broken depth agrees
  within one cell with the depth to which the unbroken model's (every face glued) effective normal traction
  exceeds T (measured: 20 m against 15 m); with 1, 10 and 40 steps the final broken area is the same (500 m^2, the
  16 faces of the clay), and the first break comes within a step after T / max(t_N') of the end time, where the
  unbroken (linear) model's largest traction reaches T (4.25 yr; measured 4.5 yr with 40 steps).
  With c = 100 kPa the crack's tip also breaks in shear, in cascades of rounds of Newton at fixed load: the same
  broken faces and break times in every step on 1 and 2 ranks, and no intact face beyond its strength at any
  step's converged state.
- A restart of the sheared blocks from the checkpoint before the break equals the uninterrupted run across it
  (to 1e-10).
"""

import os

import numpy as np
import pytest

from conftest import FISSURE_BOX, compare_runs, run_scene
from pfault.faults import breaking as br
from pfault.faults import contact as ct
from pfault.faults.settings import FaultSettings
from pfault.post import rundir

E, NU = 10e6, 0.25
G = E / (2 * (1 + NU))
T = 1e5                  # Pa, tensile strength
L = 2.0                  # m, the bar's length (plane at x = 1)
STRETCH = T * L / E      # m, the breaking stretch of the bar
EPS = 1e-8

BAR = f"""# a bar 2 m x 1 m x 1 m pulled apart along x across a candidate plane x = 1 (uniaxial stress)
-pfault_scene bar
-pfault_mesh_generator box
-pfault_box_size 2,1,1
-pfault_box_cells 4,2,2
-pfault_box_materials rock
-pfault_box_fault_planes fissure:x:1
-pfault_material_rock_young_modulus {E}
-pfault_material_rock_poisson_ratio {NU}
-pfault_faults fissure
-pfault_fault_fissure_cohesion 1*MPa
-pfault_fault_fissure_friction_angle 30
-pfault_fault_fissure_tensile_strength {T}
-pfault_bc_xmin_type roller
-pfault_bc_ymin_type roller
-pfault_bc_bottom_type roller
-pfault_bc_xmax_type displacement
-pfault_bc_xmax_components x
-pfault_bc_xmax_displacement {STRETCH},0,0
-pfault_bc_xmax_history 0:0,1:0.5,2:{1 - EPS!r},3:{1 + EPS!r},4:2
-pfault_time_end 4
-pfault_time_steps 4
-pfault_solver mumps
"""

# sheared blocks: pressure p0 and shear tau0 at s = 1, cohesion c, residual c_r; s* where tau = c + p tan(phi)
P0, TAU0, C, C_R = 1e6, 1e6, 2e5, 1e5
TAN_PHI = np.tan(np.radians(30.0))
S_BREAK = C / (TAU0 - P0 * TAN_PHI)
SZZ = -P0 / 3.0          # sigma_zz of the uniform state: -p lambda / (lambda + 2 mu) = -p / 3 at nu = 1/4
SHEAR = f"""# two blocks pressed together (p) and sheared along z (tau), both in proportion to the history s
-pfault_scene sheared_blocks
-pfault_mesh_generator box
-pfault_box_size 2,1,1
-pfault_box_cells 4,2,2
-pfault_box_materials rock
-pfault_box_fault_planes fault:x:1
-pfault_material_rock_young_modulus {E}
-pfault_material_rock_poisson_ratio {NU}
-pfault_faults fault
-pfault_fault_fault_cohesion {C}
-pfault_fault_fault_residual_cohesion {C_R}
-pfault_fault_fault_friction_angle 30
-pfault_fault_fault_tensile_strength {T}
-pfault_bc_xmin_type fixed
-pfault_bc_xmax_type displacement
-pfault_bc_xmax_components z
-pfault_bc_xmax_displacement 0,0,{TAU0 * L / G!r}
-pfault_bc_xmax_traction {-P0},0,0
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_bc_top_type traction
-pfault_bc_bottom_type traction
-pfault_bc_top_traction {TAU0},0,{SZZ!r}
-pfault_bc_bottom_traction {-TAU0},0,{-SZZ!r}
-pfault_bc_xmax_history 0:0,1:{S_BREAK * (1 - EPS)!r},2:{S_BREAK * (1 + EPS)!r},3:1
-pfault_bc_top_history 0:0,1:{S_BREAK * (1 - EPS)!r},2:{S_BREAK * (1 + EPS)!r},3:1
-pfault_bc_bottom_history 0:0,1:{S_BREAK * (1 - EPS)!r},2:{S_BREAK * (1 + EPS)!r},3:1
-pfault_time_end 3
-pfault_time_steps 3
-pfault_solver mumps
"""


def write_scene(directory, text, name):
    path = os.path.join(str(directory), name + ".opts")
    with open(path, "w") as fh:
        fh.write(text)
    return path


def fault_steps(out):
    first = rundir.read_fault(str(out), 0)
    return [first.cell_data] + [rundir.read_fault(str(out), k).cell_data for k in range(1, first.num_steps)]


@pytest.mark.parametrize("ranks", [1, 2])
def test_bar_breaks_at_its_tensile_strength(tmp_path, ranks):
    scene = write_scene(tmp_path, BAR, "bar")
    _, s = run_scene(scene, tmp_path / "out", ranks=ranks)
    assert s["converged"]
    steps = fault_steps(tmp_path / "out")          # steps 0..4
    nf = len(steps[0]["broken"])
    assert nf == 8
    for k in (1, 2):                               # stress 0.5 T, (1 - 1e-8) T: intact, glued
        d = steps[k]
        assert not d["broken"].any() and np.isnan(d["break_time"]).all()
        assert np.abs(d["opening"]).max() < 1e-14 * STRETCH
        assert np.all(d["state"] == ct.STICK)
        stress = (0.5 if k == 1 else 1 - EPS) * T
        assert np.allclose(d["traction_normal"], stress, rtol=1e-10, atol=0)
    for k in (3, 4):                               # (1 + 1e-8) T, then twice the stretch: broken, open, free
        d = steps[k]
        assert d["broken"].all() and np.all(d["break_time"] == 3.0)
        assert np.all(d["state"] == ct.OPEN)
        stretch = (1 + EPS if k == 3 else 2.0) * STRETCH
        assert np.allclose(d["opening"], stretch, rtol=1e-10, atol=0)
        assert np.abs(d["traction_normal"]).max() < 1e-9 * T
    rec = s["steps"][2]
    assert rec["faces_broken_step"] == nf and rec["breaking_passes"] == 1
    f = s["faults"]["fissure"]
    assert f["faces_broken"] == nf and f["first_break_time_s"] == 3.0
    assert f["broken_area_m2"] == pytest.approx(1.0, rel=1e-12)
    assert f["broken_depth_m"] == pytest.approx(1.0, rel=1e-12)      # the whole height below the top
    assert f["broken_length_m"] == pytest.approx(1.0, rel=1e-12)     # its trace across the top


# the bar across a pre-existing cohesive fault (c = 1 MPa: its apex c / tan(phi) is 1.73 MPa), pressed to -1 kPa of
# uniaxial stress, then pulled to +1 kPa
PULL = 1e3                                # Pa
PRESSED_PULLED = BAR.replace(f"-pfault_fault_fissure_tensile_strength {T}\n", "").replace(
    f"-pfault_bc_xmax_displacement {STRETCH},0,0", f"-pfault_bc_xmax_displacement {PULL * L / E!r},0,0").replace(
    f"-pfault_bc_xmax_history 0:0,1:0.5,2:{1 - EPS!r},3:{1 + EPS!r},4:2",
    "-pfault_bc_xmax_history 0:0,1:-1,2:1").replace("-pfault_time_end 4\n-pfault_time_steps 4",
                                                    "-pfault_time_end 2\n-pfault_time_steps 2")


def test_a_fault_whose_cutoff_is_at_zero_opens_at_zero_normal_traction(tmp_path):
    """-pfault_fault_<name>_tension_cutoff zero: the cohesive fault, closed and stuck at -1 kPa, opens by the whole
    stretch with no traction at +1 kPa; with the default cut-off at the apex it stays closed and carries the +1 kPa
    (1 rank)."""
    assert "tensile_strength" not in PRESSED_PULLED and "history 0:0,1:-1,2:1" in PRESSED_PULLED
    scene = write_scene(tmp_path, PRESSED_PULLED, "pulled")
    for cutoff in ("zero", "apex"):
        extra = ["-pfault_fault_fissure_tension_cutoff", "zero"] if cutoff == "zero" else []
        _, s = run_scene(scene, tmp_path / cutoff, extra=extra)
        assert s["converged"], cutoff
        steps = fault_steps(tmp_path / cutoff)
        pressed, pulled = steps[1], steps[2]
        assert np.all(pressed["state"] == ct.STICK), cutoff
        assert np.allclose(pressed["traction_normal_effective"], -PULL, rtol=1e-10, atol=0), cutoff
        if cutoff == "zero":
            assert np.all(pulled["state"] == ct.OPEN)
            assert np.allclose(pulled["opening"], PULL * L / E, rtol=1e-10, atol=0)
            assert np.abs(pulled["traction_normal_effective"]).max() < 1e-9 * PULL
        else:
            assert np.all(pulled["state"] == ct.STICK)
            assert np.allclose(pulled["traction_normal_effective"], PULL, rtol=1e-10, atol=0)
            assert np.abs(pulled["opening"]).max() < 1e-12 * PULL * L / E


@pytest.mark.parametrize("ranks", [1, 2])
def test_blocks_break_in_shear_on_their_cohesion(tmp_path, ranks):
    scene = write_scene(tmp_path, SHEAR, "shear")
    _, s = run_scene(scene, tmp_path / "out", ranks=ranks)
    assert s["converged"]
    steps = fault_steps(tmp_path / "out")
    d = steps[1]                                   # s* (1 - 1e-8): intact, glued, the uniform state's traction
    assert not d["broken"].any() and np.all(d["state"] == ct.STICK)
    assert np.abs(d["slip_magnitude"]).max() < 1e-14 * TAU0 * L / G
    assert np.allclose(d["traction_normal"], -P0 * S_BREAK * (1 - EPS), rtol=1e-10, atol=0)
    assert np.allclose(d["traction_shear"][:, 2], TAU0 * S_BREAK * (1 - EPS), rtol=1e-10, atol=0)
    for k in (2, 3):       # s* (1 + 1e-8), then 1: broken; slipping on c_r, or open at its apex c_r / tan(phi)
        d = steps[k]
        assert d["broken"].all() and np.all(d["break_time"] == 2.0)
        slip, opn = d["state"] == ct.SLIP, d["state"] == ct.OPEN
        assert np.all(slip | opn) and slip.sum() >= 4
        tau = np.linalg.norm(d["traction_shear"], axis=1)
        tn = d["traction_normal_effective"]
        assert np.allclose(tau[slip], C_R - TAN_PHI * tn[slip], rtol=1e-9, atol=0)
        assert np.allclose(tn[opn], C_R / TAN_PHI, rtol=1e-9, atol=0) and np.all(tau[opn] < 1e-9 * C_R)
        assert d["slip_magnitude"].min() > 0
    assert s["steps"][1]["faces_broken_step"] == 8
    assert s["faults"]["fault"]["first_break_time_s"] == 2.0


@pytest.mark.parametrize("ranks", [1, 2])
def test_restart_across_a_break_equals_the_uninterrupted_run(tmp_path, ranks):
    """The sheared blocks (the bar, traction-free once broken, has stresses of round-off to compare)."""
    scene = write_scene(tmp_path, SHEAR, "shear")
    ref, part = tmp_path / "ref", tmp_path / "part"
    _, s_ref = run_scene(scene, ref, ranks=ranks)
    _, s_part = run_scene(scene, part, ranks=ranks, extra=["-pfault_time_steps", "1", "-pfault_time_end", "1"])
    assert s_part["completed_steps"] == [1] and s_part["faults"]["fault"]["faces_broken"] == 0
    _, s = run_scene(scene, part, ranks=ranks, extra=["-pfault_restart", str(part)])
    assert s["completed_steps"] == [1, 2, 3] and s["faults"]["fault"]["faces_broken"] == 8
    keys = ("faces_broken", "broken_area_m2", "broken_depth_m", "broken_length_m", "first_break_time_s")
    assert [s["faults"]["fault"][k] for k in keys] == [s_ref["faults"]["fault"][k] for k in keys]
    compare_runs(ref, part, 1e-10)


YEAR = 365.25 * 86400.0
BOX_T = 15e3            # Pa
BOX_CELL = 5.0          # m, the cells' height
BOX = ["-pfault_box_cells", "32,2,20", "-pfault_box_size", "400,25,100", "-pfault_box_fault_planes",
       "fissure:x:387.5:0:25:-60:0", "-pfault_fault_fissure_cohesion", "1*MPa"]


def test_fissure_depth_and_extent_in_a_layered_box(tmp_path):
    _, glued = run_scene(FISSURE_BOX, tmp_path / "glued", extra=[
        *BOX, "-pfault_fault_fissure_tensile_strength", "1e12", "-pfault_time_steps", "1"])
    assert glued["faults"]["fissure"]["faces_broken"] == 0
    snap = rundir.read_fault(str(tmp_path / "glued"), -1)
    tn = snap.cell_data["traction_normal_effective"]
    top = 0.0                                     # the box's land surface
    depth = top - snap.points[snap.cells][:, :, 2].min(axis=1)
    pulled = tn > BOX_T
    assert pulled.any() and not pulled.all()
    expected_depth = depth[pulled].max()
    first = 10 * YEAR * BOX_T / tn.max()          # linear: the largest traction reaches T
    area = {}
    for n in (1, 10, 40):
        _, s = run_scene(FISSURE_BOX, tmp_path / f"n{n}", extra=[
            *BOX, "-pfault_fault_fissure_tensile_strength", f"{BOX_T}", "-pfault_time_steps", str(n)])
        assert s["converged"], n
        f = s["faults"]["fissure"]
        assert abs(f["broken_depth_m"] - expected_depth) <= BOX_CELL, (n, f["broken_depth_m"], expected_depth)
        assert f["broken_length_m"] == pytest.approx(25.0, rel=1e-12)      # across the box's width
        assert first <= f["first_break_time_s"] <= first + 10 * YEAR / n, (n, f["first_break_time_s"], first)
        assert f["faces_open"] <= f["faces_broken"]
        area[n] = f["broken_area_m2"]
    row = 25.0 * BOX_CELL                          # one row of faces across the width
    assert max(area.values()) - min(area.values()) <= row, area


def test_the_cascade_does_not_depend_on_the_partition(tmp_path):
    """The fissure box's plane with c = 100 kPa: the crack's tip breaks in shear below the clay, in cascades of 2-3
    rounds of Newton at fixed load (36 faces by year 10 in 10 steps), some rounds ended before convergence where
    the iterate's estimated error settled every verdict (pfault.solver.policy.Settling); the broken faces and
    their break times of every step are the same on 1 and 2 ranks, and at every step's converged state no intact
    face exceeds its strength."""
    import h5py
    extra = [*BOX[:-1], "100*kPa", "-pfault_fault_fissure_tensile_strength", f"{BOX_T}", "-pfault_time_steps", "10",
             "-pfault_contact_monitor"]
    procs, runs = {}, {}
    for r in (1, 2):
        procs[r], runs[r] = run_scene(FISSURE_BOX, tmp_path / f"r{r}", ranks=r, extra=extra)
    assert runs[1]["faults"]["fissure"]["faces_broken"] > 16          # beyond the clay's tension zone
    assert max(r["breaking_passes"] for r in runs[1]["steps"]) >= 2
    assert all("(error " in procs[r].stdout for r in (1, 2))         # verdicts taken before convergence
    assert [r["faces_broken_step"] for r in runs[1]["steps"]] == [r["faces_broken_step"] for r in runs[2]["steps"]]
    fissure = FaultSettings("fissure", 100e3, 30.0, "lagrange", 0.0, 0.0, BOX_T, 0.0)
    with h5py.File(tmp_path / "r1" / "fault.h5", "r") as a, h5py.File(tmp_path / "r2" / "fault.h5", "r") as b:
        assert sorted(a["steps"]) == sorted(b["steps"])
        for step in a["steps"]:
            x, y = a["steps"][step], b["steps"][step]
            assert np.array_equal(x["broken"][()], y["broken"][()]), step
            assert np.array_equal(x["break_time"][()], y["break_time"][()], equal_nan=True), step
            intact = x["broken"][()] == 0
            t = np.zeros((len(intact), 3))
            t[:, 0], t[:, 1] = x["traction_normal_effective"][()], np.linalg.norm(x["traction_shear"][()], axis=1)
            strength = br.face_strength([fissure], np.zeros(len(intact), np.int64))
            assert np.all(br.margin(strength, t)[intact] <= 1e-9 * 100e3), step
