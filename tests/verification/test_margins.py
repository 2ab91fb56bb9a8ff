"""Margins to failure (pfault.margins, pfault.faults.margins): the further uniform drawdown at which a stuck fault face
slips, opens or breaks, checked against a closed form and by running the scene that far.

- A block with a fault dipping 45 degrees through it (benchmarks/faulted_aquifer_mesh.py --slab, one material's
  properties everywhere), laterally confined on a fixed bottom, loaded by a vertical traction sigma on its top and a
  uniform drawdown h: the oedometric state is uniform (P1 exact, every face stuck) and every face's margin is the
  closed form below, at time 0 (unloaded) and after the first step.
- The faulted aquifer (config/faulted_aquifer.opts on a 40 m slice of the block at size factor 2), Wuxi (size
  factor 3, at 3 years: later every face of the fissure is open) and Wuxi's fissure plane as a candidate surface
  (config/wuxi_fissure.opts, after a year): the run is continued from its checkpoint with the drawdown raised by the
  smallest margin reported plus 2 % and minus 2 % (the tables extended after the checkpoint's time): the face
  reported slips (breaks) in the first and is stuck (intact) in the second.
- 1 and 2 ranks give the same margins; the iterative solver's are MUMPS's to 1e-4 relative, the accuracy they are
  stated to, on 1 and 2 ranks; the steps are the same with margins and without.
- A fault beside soils that remember: the faulted aquifer's slice with its sand given compression indices, after
  1.6 years in one step (11.68 m drawn down, the sand compacting on its virgin line, a face 0.054 m from
  slipping), continued likewise. The response's Jacobian takes the virgin line in the cells on their cap
  (pfault.soils.term.SoilTerm.margin_configuration).
"""

import json
import os

import h5py
import numpy as np
import pytest

from conftest import run, run_scene, soil_aquifer_slice, WUXI

RHO_G = 1000.0 * 9.80665
SIGMA, H1, COHESION, PHI, NU, DIP = 0.5e6, 57.0, 0.1e6, 20.0, 0.25, 45.0
BLOCK = """# a block with a fault dipping 45 degrees through it, one material's properties everywhere
-pfault_scene margin_block
-pfault_material_rock_young_modulus 10*MPa
-pfault_material_rock_poisson_ratio {nu}
-pfault_material_clay_young_modulus 10*MPa
-pfault_material_clay_poisson_ratio {nu}
-pfault_material_sand_young_modulus 10*MPa
-pfault_material_sand_poisson_ratio {nu}
-pfault_faults fault
-pfault_fault_fault_cohesion {c}
-pfault_fault_fault_friction_angle {phi}
-pfault_bc_bottom_type fixed
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_bc_top_type traction
-pfault_bc_top_traction 0,0,-{sigma}
-pfault_bc_top_history 0:0,1:1
-pfault_time_end 1
-pfault_time_steps 1
-pfault_solver mumps
""".format(nu=NU, c=COHESION, phi=PHI, sigma=SIGMA)
MATERIALS = ("rock", "clay", "sand")


def block_margin(sigma, h):
    """The closed form: the oedometric state under the top traction sigma and the drawdown h (tension positive,
    alpha = 1): sigma_zz = -sigma, sigma_xx = -sigma nu/(1-nu) + rho_w g h (1-2nu)/(1-nu), the faces' pore pressure
    -rho_w g h (no initial pressure: not geostatic). On the plane of dip delta the shear traction and the
    effective normal traction are affine in h, tau = a0 + a1 h and t_N' = b0 + b1 h, and the face slips where
    tau = c - tan(phi) t_N': the margin is that h less the drawdown h already there."""
    k, m = NU / (1 - NU), (1 - 2 * NU) / (1 - NU)
    sin, cos = np.sin(np.radians(DIP)), np.cos(np.radians(DIP))
    s2, c2, sc = sin * sin, cos * cos, sin * cos
    a0, a1 = (-sigma * k + sigma) * sc, RHO_G * m * sc                # (sigma_xx - sigma_zz) sin cos
    b0, b1 = -sigma * k * s2 - sigma * c2, RHO_G * m * s2 - RHO_G     # sigma_xx sin^2 + sigma_zz cos^2 - rho_w g h
    tan = np.tan(np.radians(PHI))
    return (COHESION - tan * b0 - a0) / (a1 + tan * b1) - h


def table(points):
    return ",".join(f"{t}:{v!r}" for t, v in points)


def fault_steps(run_dir):
    """{step: {dataset: array}} of fault.h5, in the serial face order."""
    with h5py.File(os.path.join(run_dir, "fault.h5"), "r") as f:
        return {int(k): {name: g[name][()] for name in g} for k, g in f["steps"].items()}


def continue_by(scene, run_dir, out, extra, times, tables, margin, factor):
    """Continue ``run_dir`` one step further (``times``: (checkpoint time, end time, steps) as option values)
    with every loaded material's drawdown raised by ``factor`` times ``margin`` (``tables``: {material: drawdown
    at the checkpoint, m}); returns the continued run's fault.h5 at its last step."""
    t_ckpt, t_end, steps = times
    raised = [f"-pfault_material_{name}_head_drawdown" for name in tables]
    values = [table([(0, 0), (t_ckpt, h), (t_end, h + factor * margin)]) for h in tables.values()]
    run_scene(scene, out, extra=[*extra, "-pfault_restart", str(run_dir), "-pfault_time_end", t_end,
                                 "-pfault_time_steps", str(steps), *[v for pair in zip(raised, values) for v in pair]])
    steps_out = fault_steps(out)
    return steps_out[max(steps_out)]


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    d = tmp_path_factory.mktemp("margin_block")
    msh = str(d / "block.msh")
    run([os.path.join("benchmarks", "faulted_aquifer_mesh.py"), msh, "--slab", "--fault-size", "5",
         "--dip", f"{DIP:g}", "--depth", "20", "--clay", "10", "--fault-x", "40", "--length", "100"], timeout=300)
    scene = d / "block.opts"
    scene.write_text(BLOCK)
    extra = ["-pfault_mesh_file", msh, *[v for name in MATERIALS
                                         for v in (f"-pfault_material_{name}_head_drawdown", f"0:0,1:{H1:g}")]]
    runs = {ranks: run_scene(str(scene), d / f"out{ranks}", ranks=ranks, extra=extra)[1] for ranks in (1, 2)}
    return str(scene), d, extra, runs


def test_block_margins_are_the_closed_form_on_every_face(block):
    """Every face's margin at time 0 (no load: 112.44 m) and after the first step (sigma = 0.5 MPa, 57 m drawn down:
    4.458 m) is the closed form to 1e-9; every face would slip; the summary names one of them and its area is
    within 5 m and 10 m but not 1 m."""
    _, d, _, runs = block
    steps = fault_steps(d / "out1")
    for step, (sigma, h) in {0: (0.0, 0.0), 1: (SIGMA, H1)}.items():
        want = block_margin(sigma, h)
        np.testing.assert_allclose(steps[step]["margin_drawdown_m"], want, rtol=1e-9)
        np.testing.assert_allclose(steps[step]["margin_pore_pressure_pa"], RHO_G * want, rtol=1e-9)
        assert np.all(steps[step]["margin_mode"] == 0) and np.all(steps[step]["state"] == 0)
    assert block_margin(0.0, 0.0) == pytest.approx(112.444, abs=1e-3)
    assert block_margin(SIGMA, H1) == pytest.approx(4.458, abs=1e-3)
    m = runs[1]["faults"]["fault"]["margin"]
    n = runs[1]["mesh"]["fault_faces"]
    assert m["min_drawdown_m"] == pytest.approx(block_margin(SIGMA, H1), rel=1e-9)
    assert m["min_pore_pressure_pa"] == pytest.approx(RHO_G * block_margin(SIGMA, H1), rel=1e-9)
    assert m["min_mode"] == "slip" and 0 <= m["min_face"] < n
    assert m["faces_failed"] == 0 and m["faces_never"] == 0 and m["failed_area_m2"] == 0.0
    whole = 5.0 * 20.0 / np.sin(np.radians(DIP))        # the slab's thickness times the fault's length down dip
    assert m["area_within_m2"] == {"1": 0.0, "5": pytest.approx(whole, rel=1e-12),
                                   "10": pytest.approx(whole, rel=1e-12)}
    assert runs[1]["steps"][-1]["margin_solve"]["converged"]


def test_block_margins_on_one_and_two_ranks(block):
    _, d, _, runs = block
    one, two = fault_steps(d / "out1"), fault_steps(d / "out2")
    for step in one:
        np.testing.assert_allclose(two[step]["margin_drawdown_m"], one[step]["margin_drawdown_m"], rtol=1e-9)
    a, b = runs[1]["faults"]["fault"]["margin"], runs[2]["faults"]["fault"]["margin"]
    assert b["min_drawdown_m"] == pytest.approx(a["min_drawdown_m"], rel=1e-9)


def test_block_margin_solve_keeps_the_step_jacobian(block):
    """Every face stuck after the step and under a further drawdown: the margins' Jacobian is the last Newton
    Jacobian, which the margin solve uses as it is, with its factors: no Jacobian assembled, no factorisation, no
    preconditioner set up, on 1 and 2 ranks; the system is time 0's (every face stuck, the same loaded cells and
    right-hand side), whose rate it takes: no Krylov iteration."""
    _, _, _, runs = block
    for ranks in (1, 2):
        records = [r["margin_solve"] for r in runs[ranks]["steps"] if "margin_solve" in r]
        assert len(records) == 1 and records[0]["solved"] and records[0]["converged"], ranks
        assert (records[0]["jacobians"], records[0]["factorizations"], records[0]["pc_setups"]) == (0, 0, 0), ranks
        assert records[0]["ksp_its"] == 0, ranks


@pytest.mark.parametrize("factor, fails", [(1.02, True), (0.98, False)])
def test_block_slips_past_its_margin(block, tmp_path, factor, fails):
    """Drawn down 2 % past the margin every face slips; 2 % short of it none does."""
    scene, d, extra, runs = block
    margin = runs[1]["faults"]["fault"]["margin"]["min_drawdown_m"]
    last = continue_by(scene, d / "out1", tmp_path / "more", extra, ("1", "2", 2), dict.fromkeys(MATERIALS, H1),
                       margin, factor)
    assert np.all(last["state"] == 1) if fails else np.all(last["state"] == 0)


# -- the faulted aquifer and Wuxi -------------------------------------------------------------------------------
AQUIFER = "config/faulted_aquifer.opts"
FISSURE = "config/wuxi_fissure.opts"


@pytest.fixture(scope="module")
def aquifer(tmp_path_factory):
    d = tmp_path_factory.mktemp("margin_aquifer")
    msh = str(d / "slice.msh")
    run([os.path.join("benchmarks", "faulted_aquifer_mesh.py"), msh, "--strike-length", "40",
         "--size-factor", "2"], timeout=300)
    extra = ["-pfault_mesh_file", msh]
    runs = {ranks: run_scene(AQUIFER, d / f"out{ranks}", ranks=ranks, extra=extra)[1] for ranks in (1, 2)}
    return d, extra, runs


def test_aquifer_margins_fall_with_the_drawdown_until_a_face_slips(aquifer):
    """While every face sticks the response is linear: each step's margins are the last ones less the step's 7.3 m
    of drawdown, to 1e-9; the first face slips in the step whose drawdown passes the margin of the initial state;
    faces slipping have a zero margin in the slip mode."""
    d, _, runs = aquifer
    s = runs[1]
    margins = {r["step"]: r["faults"]["fault"]["margin"] for r in s["steps"]}
    first = margins[0]["min_drawdown_m"]
    steps = fault_steps(d / "out1")
    slipping = [r["step"] for r in s["steps"] if r["slip"] + r["open"] > 0]
    assert slipping and 7.3 * (slipping[0] - 1) < first <= 7.3 * slipping[0]
    for k in range(1, slipping[0]):
        np.testing.assert_allclose(steps[k]["margin_drawdown_m"], steps[k - 1]["margin_drawdown_m"] - 7.3,
                                   rtol=1e-9)
    last = steps[max(steps)]
    failed = last["state"] != 0
    assert np.all(last["margin_drawdown_m"][failed] == 0.0)
    assert np.all(last["margin_mode"][failed] == last["state"][failed] - 1)      # slip 1 -> 0, open 2 -> 1
    assert np.all(last["margin_drawdown_m"][~failed] > 0.0)
    summary = s["faults"]["fault"]["margin"]
    assert summary == margins[max(margins)]
    assert summary["faces_failed"] == int(np.count_nonzero(failed))
    assert summary["min_drawdown_m"] == pytest.approx(np.min(last["margin_drawdown_m"][~failed]), rel=1e-14)


def test_aquifer_margins_on_one_and_two_ranks(aquifer):
    d, _, runs = aquifer
    one, two = fault_steps(d / "out1"), fault_steps(d / "out2")
    assert sorted(one) == sorted(two)
    for step in one:
        np.testing.assert_allclose(two[step]["margin_drawdown_m"], one[step]["margin_drawdown_m"], rtol=1e-7,
                                   atol=1e-8)
        assert np.array_equal(two[step]["margin_mode"], one[step]["margin_mode"])
    a, b = runs[1]["faults"]["fault"]["margin"], runs[2]["faults"]["fault"]["margin"]
    assert b["min_face"] == a["min_face"] and b["min_mode"] == a["min_mode"]
    assert b["min_xyz_m"] == pytest.approx(a["min_xyz_m"], rel=1e-12)


def test_aquifer_margin_solve_keeps_the_iterative_preconditioner(aquifer):
    """The iterative solver (AMG in a Schur fieldsplit) on 1 and 2 ranks: in the steps where faces slip the margin
    solve assembles the Jacobian at the converged state (a slipping face's rows depend on it) and keeps the
    preconditioner Newton's last Jacobian, of the same faces' states, was given: no preconditioner set up. While
    every face sticks (years 1 and 2) the system is the last output time's, whose rate it takes: no Krylov
    iteration. Its margins are MUMPS's (the direct solve of the same run on as many ranks) to 1e-4 relative, the
    accuracy they are stated to (pfault.solver.policy.MARGIN_RTOL)."""
    d, extra, _ = aquifer
    for ranks in (1, 2):
        _, s = run_scene(AQUIFER, d / f"iterative{ranks}", ranks=ranks, extra=[*extra, "-pfault_solver", "iterative"])
        slipping = [r for r in s["steps"] if r["slip"] > 0]
        assert len(slipping) == 8, ranks
        for r in slipping:
            solve = r["margin_solve"]
            assert solve["converged"] and (solve["jacobians"], solve["pc_setups"]) == (1, 0), (ranks, r["step"])
        assert [s["steps"][k]["margin_solve"]["ksp_its"] for k in (1, 2)] == [0, 0], ranks
        mumps, iterative = fault_steps(d / f"out{ranks}"), fault_steps(d / f"iterative{ranks}")
        assert sorted(iterative) == sorted(mumps)
        for k in mumps:
            np.testing.assert_allclose(iterative[k]["margin_drawdown_m"], mumps[k]["margin_drawdown_m"], rtol=1e-4,
                                       atol=0.0)
            assert np.array_equal(iterative[k]["margin_mode"], mumps[k]["margin_mode"]), (ranks, k)


def test_aquifer_steps_are_the_same_without_margins(aquifer):
    """The margins change none of the steps: MUMPS on 2 ranks with its factor reuse takes the same Newton and
    Krylov iterations and factorisations in every step with margins as without (-pfault_margins false). The margin
    solve's iterations on kept factors once counted toward the next step's refactoring: year 10 took 7 Krylov
    iterations and 2 factorisations with margins, 9 and 1 without."""
    d, extra, runs = aquifer
    _, off = run_scene(AQUIFER, d / "off", ranks=2, extra=[*extra, "-pfault_margins", "false"])

    def counts(s):
        return [(r["newton_its"], r["ksp_its"], r.get("factorizations")) for r in s["steps"]]
    assert counts(runs[2]) == counts(off)
    assert sum(r.get("factorizations") or 0 for r in off["steps"]) >= 10          # the factor reuse at work
    assert all("margin_solve" not in r for r in off["steps"])


@pytest.mark.parametrize("factor, fails", [(1.02, True), (0.98, False)])
def test_aquifer_face_fails_past_its_margin(aquifer, tmp_path, factor, fails):
    d, extra, runs = aquifer
    m = runs[1]["faults"]["fault"]["margin"]
    last = continue_by(AQUIFER, d / "out1", tmp_path / "more", extra, ("10*year", "11*year", 11), {"sand": 73.0},
                       m["min_drawdown_m"], factor)
    assert (last["state"][m["min_face"]] != 0) == fails


@pytest.fixture(scope="module")
def wuxi(tmp_path_factory):
    d = tmp_path_factory.mktemp("margin_wuxi")
    extra = ["-pfault_mesh_size_factor", "3"]
    _, s = run_scene(WUXI, d / "out", extra=[*extra, "-pfault_time_end", "3*year", "-pfault_time_steps", "3"])
    return d, extra, s


@pytest.mark.parametrize("factor, fails", [(1.02, True), (0.98, False)])
def test_wuxi_face_fails_past_its_margin(wuxi, tmp_path, factor, fails):
    """At 3 years (6 m of drawdown in the sands, 3 m in the clays) most of the fissure is open; the next face
    fails after 5.2 cm more in both (measured)."""
    d, extra, s = wuxi
    m = s["faults"]["fissure"]["margin"]
    assert 0.0 < m["min_drawdown_m"] < 1.0 and m["faces_failed"] > 0
    last = continue_by(WUXI, d / "out", tmp_path / "more", extra, ("3*year", "4*year", 4),
                       {"sand": 6.0, "clay": 3.0}, m["min_drawdown_m"], factor)
    assert (last["state"][m["min_face"]] != 0) == fails
    with open(os.path.join(d / "out", "summary.json")) as fh:
        assert json.load(fh)["steps"][-1]["faults"]["fissure"]["margin"] == m


@pytest.fixture(scope="module")
def fissure(tmp_path_factory):
    d = tmp_path_factory.mktemp("margin_fissure")
    extra = ["-pfault_mesh_size_factor", "3"]
    _, s = run_scene(FISSURE, d / "out", extra=[*extra, "-pfault_time_end", "1*year", "-pfault_time_steps", "1"])
    return d, extra, s


@pytest.mark.parametrize("factor, fails", [(1.02, True), (0.98, False)])
def test_wuxi_fissure_face_breaks_past_its_margin(fissure, tmp_path, factor, fails):
    """Wuxi's fissure plane as a candidate surface (config/wuxi_fissure.opts) after its first year: 57 faces
    broke; the next intact face breaks after 2.7 cm more (measured), 2 % past it and not 2 % short."""
    d, extra, s = fissure
    m = s["faults"]["fissure"]["margin"]
    assert m["min_mode"] == "break" and 0.0 < m["min_drawdown_m"] < 1.0 and m["faces_failed"] > 0
    last = continue_by(FISSURE, d / "out", tmp_path / "more", extra, ("1*year", "2*year", 2),
                       {"sand": 2.0, "clay": 1.0}, m["min_drawdown_m"], factor)
    assert bool(last["broken"][m["min_face"]]) == fails
    assert int(last["broken"].sum()) == m["faces_failed"] + int(fails)


# -- a fault beside soils that remember ---------------------------------------------------------------------------
SOIL_YEARS = 1.6        # the first stage: 7.3 m a year drawn down in the sand


@pytest.fixture(scope="module")
def soil_aquifer(tmp_path_factory):
    """config/faulted_aquifer.opts on its 40 m slice at size factor 2 (1,257 tetrahedra), the sand normally
    consolidated with Cc 0.05 and Cr 0.01 in place of its drained modulus, run for 1.6 years in one step on 1 and 2
    ranks, where a face is near slipping (after the first year its margin is 4.1 m)."""
    d = tmp_path_factory.mktemp("margin_soil_aquifer")
    scene, msh = soil_aquifer_slice(d, 2, "soil_aquifer.opts")
    extra = ["-pfault_mesh_file", msh]
    first = ["-pfault_time_end", f"{SOIL_YEARS}*year", "-pfault_time_steps", "1"]
    runs = {ranks: run_scene(scene, d / f"out{ranks}", ranks=ranks, extra=[*extra, *first])[1]
            for ranks in (1, 2)}
    return scene, d, extra, runs


def test_soil_aquifer_margins_on_one_and_two_ranks(soil_aquifer):
    """After 1.6 years every face sticks, all 436 sand cells compact on the virgin line, and the smallest margin is
    0.0538 m (0.0889 m with the swelling line the state's own configuration gives every cell); 1 and 2 ranks give
    the same margins."""
    _, d, _, runs = soil_aquifer
    step = runs[1]["steps"][-1]
    m = step["faults"]["fault"]["margin"]
    assert step["cells_virgin"] == 436 and step["cells_elastic"] == 0 and step["margin_solve"]["converged"]
    # the virgin line in the cells on their cap is not the configuration of the last Jacobian: one of its own,
    # factored at the initial state (the gravity solve's), on the factors the factor reuse keeps after the step
    first = runs[1]["steps"][0]["margin_solve"]
    assert (first["jacobians"], first["factorizations"], first["pc_setups"]) == (1, 1, 1)
    solve = step["margin_solve"]
    assert solve["jacobians"] == 1 and solve["pc_setups"] == solve["factorizations"]
    assert m["faces_failed"] == 0 and m["min_mode"] == "slip"
    assert m["min_drawdown_m"] == pytest.approx(0.05378, rel=1e-3)
    one, two = fault_steps(d / "out1"), fault_steps(d / "out2")
    for k in one:
        np.testing.assert_allclose(two[k]["margin_drawdown_m"], one[k]["margin_drawdown_m"], rtol=1e-7, atol=1e-8)
    assert runs[2]["steps"][-1]["faults"]["fault"]["margin"]["min_face"] == m["min_face"]


@pytest.mark.parametrize("factor, fails", [(1.02, True), (0.98, False)])
def test_face_beside_soils_fails_past_its_margin(soil_aquifer, tmp_path, factor, fails):
    """The face with the smallest margin slips when the sand is drawn down 2 % past it and sticks 2 % short of it
    (with the swelling line in every cell the face slipped 2 % short of its margin)."""
    scene, d, extra, runs = soil_aquifer
    m = runs[1]["faults"]["fault"]["margin"]
    last = continue_by(scene, d / "out1", tmp_path / "more", extra, (f"{SOIL_YEARS}*year", f"{2 * SOIL_YEARS}*year",
                                                                      2), {"sand": round(7.3 * SOIL_YEARS, 9)},
                       m["min_drawdown_m"], factor)
    assert (last["state"][m["min_face"]] != 0) == fails


def test_bad_thresholds_are_one_line(tmp_path):
    proc, _ = run_scene(AQUIFER, tmp_path / "bad", extra=["-pfault_margin_thresholds", "5,-1"], check=False)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines()[-1] == ("pfault: error: -pfault_margin_thresholds: give positive drawdowns "
                                                    "in m of head, e.g. 1,5,10, got 5,-1")
    assert not (tmp_path / "bad").exists()
