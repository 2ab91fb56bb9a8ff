"""Fault contact and friction on the two-blocks scene (config/two_blocks.opts), against closed-form answers.

Two blocks [0,1] and [1,2] (x) x [0,1] x [-1,0] meet on the fault x = 1 (normal n = +x, minus side left).
Left face fixed; right face: normal traction -p and prescribed u_z = delta; top/bottom carry the shear tau and
sigma_zz of the uniform state. E = 10 MPa, nu = 0.25 (G = 4 MPa), p = 1 MPa, phi = 30 deg, L = 2 m.
- stick (G delta / L < tau_L): the uniform shear state, no jump, fault traction (-p, 0, G delta / L);
- slip: slip = delta - L tau_L / G along +z with tau_L = c + p tan(phi);
- open (right face pulled by dn along +x, no load): the right block translates, opening dn, zero traction.
Then: Newton convergence in the settled active set, a Taylor test of the Jacobian in every contact state,
Lagrange multipliers against penalty (accuracy ~ 1/k, conditioning), and 1-rank = 2-rank results.
Every 2-rank case uses a mesh whose fault faces lie on both ranks (test_fault_faces_on_both_ranks).
"""

import math
import os

import numpy as np
import pytest

from conftest import FISSURE_BOX, TWO_BLOCKS, read_last_step, run_scene, run_script
from pfault.post import meshes, rundir

SCENE = TWO_BLOCKS
P = 1.0e6                                   # normal pressure on the fault (Pa)
TAN_PHI = math.tan(math.radians(30.0))
E, NU = 10.0e6, 0.25
G = E / (2 * (1 + NU))                      # 4 MPa
LAM = E * NU / ((1 + NU) * (1 - 2 * NU))
SZZ = -P * LAM / (LAM + 2 * G)              # -1/3 MPa: sigma_zz of the uniform state (eps_yy = eps_zz = 0)
L = 2.0                                     # length of the sheared column (both blocks)
DELTA = 0.5                                 # prescribed u_z of the right face in the scene file
MESH = {1: ["-pfault_box_cells", "4,2,2"], 2: ["-pfault_box_cells", "8,4,4"]}
FINE = ["-pfault_box_cells", "8,6,6"]


def shear_tractions(tau, szz=SZZ):
    """Top and bottom tractions of the uniform state with shear stress sigma_xz = tau."""
    return ["-pfault_bc_top_traction", f"{tau!r},0,{szz!r}", "-pfault_bc_bottom_traction", f"{-tau!r},0,{-szz!r}"]


def penalty(k):
    return ["-pfault_fault_fault_method", "penalty", "-pfault_fault_fault_penalty_normal", f"{k:g}",
            "-pfault_fault_fault_penalty_tangential", f"{k:g}"]


DELTA_STICK = 0.2                           # G delta / L = 0.4 MPa < tau_L = 0.577 MPa
TAU_STICK = G * DELTA_STICK / L
COHESION = 1.0e5
OPENING = 0.01
CASES = {
    "stick": ["-pfault_bc_xmax_displacement", f"0,0,{DELTA_STICK!r}", *shear_tractions(TAU_STICK)],
    "slip": [],
    "cohesion": ["-pfault_fault_fault_cohesion", f"{COHESION!r}", *shear_tractions(COHESION + P * TAN_PHI)],
    "cycle": [],
    "open": ["-pfault_bc_xmax_components", "x,y,z", "-pfault_bc_xmax_displacement", f"{OPENING!r},0,0",
             "-pfault_bc_xmax_traction", "0,0,0", *shear_tractions(0.0, 0.0)],
    # pressed together, no shear, top and bottom free: every face sticks under a traction that varies along it
    "compression": ["-pfault_bc_xmax_displacement", "0,0,0", "-pfault_bc_top_traction", "0,0,0",
                    "-pfault_bc_bottom_traction", "0,0,0"],
}


# Newton run to -snes_rtol of its first residual (no absolute tolerance from the load)
EXACT_NEWTON = ("-snes_atol", "0")


def read_fault(outdir):
    """Fault fields of the last step (per fault face, serial face order)."""
    import meshio
    reader = meshio.xdmf.TimeSeriesReader(os.path.join(str(outdir), "fault.xdmf"))
    reader.read_points_cells()
    for k in range(reader.num_steps):
        _, _, cell_data = reader.read_data(k)
    return {name: np.asarray(v[0]) for name, v in cell_data.items()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Runs of the scene, made on first use: runs(case, ranks, extra) -> (summary, fault fields, output dir)."""
    cache = {}

    def get(case, ranks, extra=(), check=True):
        key = (case, ranks, tuple(extra))
        if key not in cache:
            out = tmp_path_factory.mktemp(f"{case}{ranks}")
            mesh = [] if "-pfault_box_cells" in extra else MESH[ranks]
            _, summary = run_scene(SCENE, out, ranks=ranks, extra=[*mesh, *CASES[case], *extra], check=check)
            cache[key] = (summary, read_fault(out) if summary is not None else None, out)
        return cache[key]
    return get


def rel(a, b):
    return np.max(np.abs(np.asarray(a) - b)) / abs(b)


# ---------------------------------------------------------------------------------------------
# what is reported: the opening of open faces, the slip of faces that have slid

@pytest.mark.parametrize("ranks", [1, 2])
def test_a_fault_that_sticks_reports_no_opening_and_no_slip(runs, ranks):
    """Two blocks pressed together: every face sticks, and its face-mean jump (P1 part and bubble part) is zero
    to the solver's tolerance (with the former traction-jump stabilisation it was S dt / A where the traction
    varies along the fault: 2.3e-4 m normal, 8.2e-5 m tangential on 1 rank); no face is open or has slid, so the
    reported opening and slip are exactly 0: in the step record, per fault and in the summary. fault.h5 keeps
    every face's jump, its state and its history flag."""
    s, f, _ = runs("compression", ranks)
    n = s["mesh"]["fault_faces"]
    step = s["steps"][-1]
    assert (step["stick"], step["slip"], step["open"]) == (n, 0, 0)
    # a pre-existing fault: every face broken from the start (the 1 m x 1 m plane, its trace 1 m), none in the run
    broken = {"faces_broken": n, "broken_area_m2": pytest.approx(1.0, rel=1e-12),
              "broken_depth_m": pytest.approx(1.0, rel=1e-12), "broken_length_m": pytest.approx(1.0, rel=1e-12),
              "first_break_time_s": None}
    nothing = {"slip_potency_m3": 0.0, "open_volume_m3": 0.0, "slipping_area_m2": 0.0, "open_area_m2": 0.0}
    assert step["faults"] == {"fault": {"faces_stuck": n, "faces_slipping": 0, "faces_open": 0,
                                        "max_opening_m": 0.0, "max_slip_m": 0.0, **nothing, **broken}}
    assert step["max_fault_opening_m"] == 0.0 and step["max_fault_slip_m"] == 0.0
    assert s["max_fault_opening_m"] == 0.0 and s["max_fault_slip_m"] == 0.0
    # the box's hexahedra, 2 m / cells along x, are split into tetrahedra each with a face on x = 1 and its
    # fourth vertex a cell's width away
    width = 2.0 / int(MESH[ranks][1].split(",")[0])
    assert s["faults"] == {"fault": {"faces": n, "beside_cell_height_m": pytest.approx(width, rel=1e-12),
                                     "max_opening_m": 0.0, "max_slip_m": 0.0, "faces_stuck": n,
                                     "faces_slipping": 0, "faces_open": 0, **nothing, **broken}}
    assert np.all(f["state"] == 0) and not np.any(f["slid"])
    assert np.max(np.abs(f["opening"])) < 1e-9 and np.max(f["slip_magnitude"]) < 1e-9


@pytest.fixture(scope="module")
def wuxi_runs(tmp_path_factory):
    """Wuxi (size factor 3) after 2 years in one step, made on first use: wuxi_runs(ranks) -> (summary, out)."""
    from conftest import WUXI
    cache = {}

    def get(ranks):
        if ranks not in cache:
            out = tmp_path_factory.mktemp(f"wuxi{ranks}")
            _, s = run_scene(WUXI, out, ranks=ranks, extra=["-pfault_mesh_size_factor", "3", "-pfault_time_steps",
                                                             "1", "-pfault_time_end", "2*year"])
            cache[ranks] = (s, out)
        return cache[ranks]
    return get


@pytest.mark.parametrize("ranks", [1, 2])
def test_reported_maxima_are_those_of_open_and_slid_faces(wuxi_runs, ranks):
    """Wuxi (size factor 3) after 2 years in one step: 74 faces stuck, 12 slipping, 540 open. The reported
    opening is the largest of the open faces' (a closed face's is not counted), the
    slip the largest of the faces that have slid; the counts per fault are those of fault.h5's states."""
    s, out = wuxi_runs(ranks)
    f = read_fault(out)
    state, slid = f["state"], f["slid"].astype(bool)
    counts = np.bincount(state, minlength=3)
    assert counts[0] > 0 and counts[1] > 0 and counts[2] > 0, counts
    assert np.array_equal(slid, state != 0)                    # one step: the faces that slid are those not stuck
    (name, per), = s["faults"].items()
    assert (per["faces"], per["faces_stuck"], per["faces_slipping"], per["faces_open"]) == (len(state), *counts)
    step = s["steps"][-1]
    assert step["faults"][name]["faces_open"] == counts[2] == step["open"]
    assert per["max_opening_m"] == s["max_fault_opening_m"] == step["max_fault_opening_m"]
    assert s["max_fault_opening_m"] == pytest.approx(f["opening"][state == 2].max(), rel=1e-12)
    assert s["max_fault_slip_m"] == pytest.approx(f["slip_magnitude"][slid].max(), rel=1e-12)
    # the fault's integrals are those of fault.h5's faces (face-mean jumps times the triangles' areas)
    import meshio
    reader = meshio.xdmf.TimeSeriesReader(os.path.join(str(out), "fault.xdmf"))
    points, cells = reader.read_points_cells()
    x = points[np.concatenate([c.data for c in cells if c.type == "triangle"])]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    assert per["slip_potency_m3"] == pytest.approx(np.sum((area * f["slip_magnitude"])[slid]), rel=1e-10)
    assert per["open_volume_m3"] == pytest.approx(np.sum((area * f["opening"])[state == 2]), rel=1e-10)
    assert per["slipping_area_m2"] == pytest.approx(area[state == 1].sum(), rel=1e-10)
    assert per["open_area_m2"] == pytest.approx(area[state == 2].sum(), rel=1e-10)
    assert per["slip_potency_m3"] == step["faults"][name]["slip_potency_m3"] > 0
    assert np.abs(f["opening"][state != 2]).max() < 1e-9, "closed faces hold (face bubbles)"


def test_fault_integrals_agree_on_1_and_2_ranks(wuxi_runs):
    """The fault's integrals and the height of the cells beside it do not depend on the partition."""
    (one, _), (two, _) = wuxi_runs(1), wuxi_runs(2)
    (name, a), = one["faults"].items()
    b = two["faults"][name]
    assert a["beside_cell_height_m"] == pytest.approx(b["beside_cell_height_m"], rel=1e-12)
    for key in ("slip_potency_m3", "open_volume_m3", "slipping_area_m2", "open_area_m2"):
        assert a[key] > 0 and a[key] == pytest.approx(b[key], rel=1e-6), key


# ---------------------------------------------------------------------------------------------
# partition

@pytest.mark.parametrize("cells,total", [("8,4,4", 32), ("8,6,6", 72), ("4,4,4", 32)])
def test_fault_faces_on_both_ranks(cells, total):
    """The 2-rank meshes used below (scene runs, 1-vs-2 comparison, Jacobian check) split the fault."""
    out = run_script("fault_partition.py", ranks=2, args=["-pfault_box_cells", cells])
    assert out["fault_faces"] == total
    assert sum(out["faces_per_rank"]) == total
    assert min(out["faces_per_rank"]) > 0, out


def test_partition_is_the_same_in_every_run():
    """The same scene on the same ranks is partitioned the same way in every run (PT-Scotch, one thread per rank;
    with its default threads the two-blocks scene came out 16/16 or 10/22 fault faces per rank at random)."""
    outs = [run_script("fault_partition.py", ranks=2, args=["-pfault_box_cells", "8,6,6"]) for _ in range(4)]
    assert len(set(outs[0]["cell_ranks"])) == 2
    for out in outs[1:]:
        assert out["cell_ranks"] == outs[0]["cell_ranks"]


# ---------------------------------------------------------------------------------------------
# stick, slip, open against the closed-form states

@pytest.mark.parametrize("ranks", [1, 2])
def test_stick_keeps_the_fault_closed_and_carries_the_elastic_shear(runs, ranks):
    s, f, _ = runs("stick", ranks)
    n = s["mesh"]["fault_faces"]
    assert s["converged"]
    step = s["steps"][-1]
    assert (step["stick"], step["slip"], step["open"]) == (n, 0, 0)
    assert np.all(f["state"] == 0)
    assert np.max(np.abs(f["opening"])) <= 1e-10
    assert np.max(f["slip_magnitude"]) <= 1e-10
    assert np.max(np.abs(f["slip"])) <= 1e-10
    assert rel(f["traction_normal"], -P) <= 1e-8
    assert rel(f["traction_shear"][:, 2], TAU_STICK) <= 1e-8
    assert np.max(np.abs(f["traction_shear"][:, :2])) <= 1e-8 * TAU_STICK


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case,cohesion,delta", [("slip", 0.0, DELTA), ("cohesion", COHESION, DELTA)])
def test_slip_matches_the_coulomb_limit(runs, ranks, case, cohesion, delta):
    s, f, _ = runs(case, ranks)
    tau_l = cohesion + P * TAN_PHI
    exact = delta - L * tau_l / G            # 0.2113249 m (c = 0), 0.1613249 m (c = 0.1 MPa)
    n = s["mesh"]["fault_faces"]
    assert s["converged"]
    step = s["steps"][-1]
    assert (step["stick"], step["slip"], step["open"]) == (0, n, 0)
    assert np.all(f["state"] == 1)
    assert rel(f["slip_magnitude"], exact) <= 1e-8
    assert rel(f["slip"][:, 2], exact) <= 1e-8          # along +z: the right block moves up
    assert np.max(np.abs(f["slip"][:, :2])) <= 1e-10
    assert np.max(np.abs(f["opening"])) <= 1e-10
    assert rel(f["traction_normal"], -P) <= 1e-8
    # on the Coulomb cone, with the measured normal traction
    limit = cohesion - f["traction_normal"] * TAN_PHI
    assert np.max(np.abs(np.linalg.norm(f["traction_shear"], axis=1) - limit) / limit) <= 1e-8
    assert rel(f["traction_shear"][:, 2], tau_l) <= 1e-8
    assert s["max_fault_slip_m"] == pytest.approx(exact, rel=1e-8)


@pytest.mark.parametrize("ranks", [1, 2])
def test_open_fault_is_traction_free(runs, ranks):
    s, f, _ = runs("open", ranks)
    n = s["mesh"]["fault_faces"]
    assert s["converged"]
    step = s["steps"][-1]
    assert (step["stick"], step["slip"], step["open"]) == (0, 0, n)
    assert np.all(f["state"] == 2)
    assert rel(f["opening"], OPENING) <= 1e-8
    assert np.max(np.abs(f["traction_normal"])) <= 1e-6 * P
    assert np.max(np.abs(f["traction_shear"])) <= 1e-6 * P
    assert np.max(f["slip_magnitude"]) <= 1e-10
    assert s["max_fault_opening_m"] == pytest.approx(OPENING, rel=1e-8)


# ---------------------------------------------------------------------------------------------
# effective stress: a uniform pore-pressure rise dp unloads the fault's friction (Terzaghi)

DP = 4.0e5                                   # Pa, alpha = 1


def pore_pressure_case(tau, effective):
    """Uniform state under total normal traction -P with the pore pressure raised by DP: sigma_zz (total) of
    that state is lam (DP - P)/(lam + 2G) - DP (eps_yy = eps_zz = 0)."""
    szz = LAM * (DP - P) / (LAM + 2 * G) - DP
    return ["-pfault_material_rock_pressure_change", f"0:0,1:{DP!r}", *shear_tractions(tau, szz),
            "-pfault_contact_effective_stress", "true" if effective else "false"]


CASES["slip_effective"] = pore_pressure_case((P - DP) * TAN_PHI, True)
CASES["slip_total"] = pore_pressure_case(P * TAN_PHI, False)


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case,sigma_n", [("slip_effective", P - DP), ("slip_total", P)])
def test_friction_acts_on_the_effective_normal_traction(runs, ranks, case, sigma_n):
    """tau_L = (P - alpha dp) tan(phi) with the effective law: slip 0.3267949 m; the total law (dry fault)
    keeps tau_L = P tan(phi): slip 0.2113249 m. The total normal traction is -P in both."""
    s, f, _ = runs(case, ranks)
    exact = DELTA - L * sigma_n * TAN_PHI / G
    n = s["mesh"]["fault_faces"]
    assert s["converged"]
    assert (s["steps"][-1]["slip"], s["steps"][-1]["open"]) == (n, 0)
    assert rel(f["slip_magnitude"], exact) <= 1e-8
    assert rel(f["slip"][:, 2], exact) <= 1e-8
    assert rel(f["traction_normal"], -P) <= 1e-8
    eff = -(P - DP) if case == "slip_effective" else -P
    assert rel(f["traction_normal_effective"], eff) <= 1e-8
    assert rel(np.linalg.norm(f["traction_shear"], axis=1), sigma_n * TAN_PHI) <= 1e-8


# the fault's pore pressure in a geostatic scene: hydrostatic below the water table, lowered by a head drawdown;
# above the lowered water table a face is dry (pressure 0) unless -pfault_contact_suction keeps the negative value
DRAWDOWN = 0.5                               # m of head, more than the depth of the upper fault faces
RHO_G = 1000.0 * 9.80665                     # -pfault_water_density times -pfault_gravity (defaults)
CASES["water_table"] = ["-pfault_bc_xmax_displacement", f"0,0,{DELTA_STICK!r}", *shear_tractions(TAU_STICK),
                        "-pfault_geostatic", "true", "-pfault_water_table", "0",
                        "-pfault_material_rock_head_drawdown", f"0:0,1:{DRAWDOWN!r}"]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("suction", [False, True])
def test_fault_pore_pressure_clamped_above_the_lowered_water_table(runs, ranks, suction):
    """t_N,eff - t_N = alpha p with p = rho_w g (-z - drawdown) at the face centroid (alpha = 1): clamped at 0 by
    default (faces at z = -1/6, -1/3 lie above the lowered water table at z = -0.5: dry), negative with
    -pfault_contact_suction true; the faces below (z = -2/3, -5/6) carry p > 0 either way."""
    s, f, out = runs("water_table", ranks, ["-pfault_contact_suction", "true" if suction else "false"])
    assert s["converged"]
    fault = rundir.read_fault(str(out))
    _, _, cen = meshes.face_geometry(fault.points, fault.cells)
    p = RHO_G * (-cen[:, 2] - DRAWDOWN)
    assert np.sum(p < 0) and np.sum(p > 0), "faces on both sides of the lowered water table"
    expected = p if suction else np.maximum(p, 0.0)
    got = fault.cell_data["traction_normal_effective"] - fault.cell_data["traction_normal"]
    assert np.max(np.abs(got - expected)) <= 1e-9 * P
# ---------------------------------------------------------------------------------------------
# Newton convergence once the active set has settled

@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case", ["slip", "cohesion"])
def test_newton_converges_quadratically_in_the_settled_active_set(runs, ranks, case):
    """SNES residual norms of the step's one semismooth Newton solve, run to -snes_rtol (EXACT_NEWTON): once the
    faces' states stop changing the iteration is Newton's on a smooth function and converges quadratically.

    Only pairs (r_k, r_k+1) with r_k > 1e-8 r_0 and r_k+1 > 1e-12 r_0 (a thousand times the round-off floor) are
    used. A linearly converging iteration with rate rho would give r_k+1/r_k^2 = rho/r_k >= 2.6e-3 1/N at
    r_k ~ 4 N even for rho = 0.01, so the bound 1e-5 1/N separates quadratic from linear convergence; the order
    is asserted two-sided, 1.5..2.5 (one triple of norms lies above round-off: no tighter claim is honest).
    """
    s, _, _ = runs(case, ranks, EXACT_NEWTON)
    step = s["steps"][-1]
    assert step["converged"] and step.get("substeps", 1) == 1
    r = np.array(step["residual_history"])
    assert r[-1] <= 1e-10 * r[0], r
    pairs = [(a, b) for a, b in zip(r, r[1:]) if a > 1e-8 * r[0] and b > 1e-12 * r[0]]
    assert len(pairs) >= 2, r
    (a0, b0), (a1, b1) = pairs[-2:]
    rho0, rho1 = b0 / a0, b1 / a1
    assert rho0 <= 0.1 and rho1 <= 0.1, r
    assert rho1 <= 0.1 * rho0, r                         # the contraction improves: superlinear
    q = [b0 / a0 ** 2, b1 / a1 ** 2]
    assert max(q) <= 1e-5, (q, r)
    order = math.log(b1 / a1) / math.log(b0 / a0)        # r_k+1 ~ C r_k^order, from r_k-1, r_k, r_k+1
    assert 1.5 <= order <= 2.5, (order, r)
    assert step["newton_its"] <= 8, step["newton_its"]


def test_factors_kept_across_state_changes_give_the_same_newton_iterates(tmp_path):
    """A direct fault solve keeps its factors while few faces differ in state from the factored Jacobian
    (FactorReuse.budget: flexible GMRES on the old factors). Wuxi on a coarse mesh, 2 ranks, run as it is and with
    -ksp_type preonly (MUMPS factors every Jacobian that changed, no Krylov method): the same Newton iterations in
    every step and the same maxima to 1e-9 (the kept factors' solves stop at -ksp_rtol 1e-8, or a tenth of the
    step's nonlinear tolerance), with fewer factorisations and more Krylov iterations (measured: 12 against 15
    factorisations, 19 against 16 Krylov iterations, the same 16 Newton iterations; the maxima 3e-15 apart)."""
    out = run_script("factor_reuse.py", ranks=2, args=["-pfault_output_dir", str(tmp_path)])
    fresh, kept = out["fresh"], out["kept"]
    assert fresh["converged"] and kept["converged"]
    assert kept["newton"] == fresh["newton"] and sum(fresh["newton"]) >= 10, (fresh, kept)
    for key in ("max_subsidence_m", "max_horizontal_displacement_m", "max_fault_opening_m", "max_fault_slip_m"):
        assert fresh[key] > 0 and kept[key] == pytest.approx(fresh[key], rel=1e-9), key
    assert kept["factorizations"] < fresh["factorizations"] and kept["krylov"] > fresh["krylov"], (fresh, kept)


def test_factor_reuse_decides_the_same_on_a_busy_machine(tmp_path):
    """The factors' reuse is decided from MUMPS's counts, not from timings, and those counts do not follow the
    machine's load: Wuxi on a coarse mesh (2 ranks, 10 steps, faces changing state in steps 1-6) run twice, the
    second time with two processes spinning on the cores until the first factorisation is made and every Krylov
    iteration slowed by 30 ms, keeps and refactors at the same Newton iterations and gives the same answer to
    round-off (measured 1.1e-14 relative in 5 of 5 pairs). With the decisions timed: 3 factorisations against 4
    in step 1 and 4.9e-5 apart; with MUMPS's PORD ordering, which orders the matrix gathered from the ranks
    otherwise when their messages arrive in another order: 6 against 8 factorisations and 1.4e-4 apart in 2 of 3
    pairs (tests/scripts/reuse_determinism.py -mat_mumps_icntl_7 4)."""
    out = run_script("reuse_determinism.py", ranks=2, args=["-pfault_output_dir", str(tmp_path)])
    quiet, slowed = out["quiet"], out["slowed"]
    assert quiet["converged"] and sum(quiet["newton"]) >= 10 and sum(quiet["factorizations"]) >= 5, quiet
    assert sum(quiet["factorizations"]) < sum(quiet["newton"])       # some Newton iterations kept the factors
    assert slowed == quiet
    assert out["max_difference"] <= 1e-12


# ---------------------------------------------------------------------------------------------
# Jacobian of the full system (Taylor test) in every state

AFFINE = ["lagrange_stick", "lagrange_open", "penalty_stick", "penalty_open"]
CURVED = ["lagrange_slip", "lagrange_slip_start", "lagrange_mixed", "penalty_slip"]
BREAKING = ["intact_mixed", "broken_mixed"]     # candidate surfaces: every face intact; half of them broken


@pytest.fixture(scope="module", params=[1, 2])
def taylor(request):
    args = [] if request.param == 1 else ["-pfault_box_cells", "4,4,4"]
    return run_script("jacobian_check.py", ranks=request.param, args=args)


def test_jacobian_taylor_remainder(taylor):
    """||F(x+hv) - F(x)|| ~ h, ||F(x+hv) - F(x) - h J v|| ~ h^2, h = 1e-2, 1e-3, 1e-4.

    Stick and open (Lagrange) and the closed-stick and open penalty branches are affine in x: there the remainder
    is round-off at every h (measured ~1e-10 against a first-order term >= 8), a stronger check than an order.
    Slip (with a slip increment, and before any increment), a mix of stick/slip/open faces and penalty slip are
    curved: order 2.000 measured (1.99 for the first interval of slip-before-increment). The same with cohesion
    (``cohesive_``: open faces carry the tensile strength c / tan(phi)). A candidate surface under the mixed
    multipliers: every face intact is held stuck, affine (remainder 1.2e-10 to 1.9e-10 against a first-order term
    >= 10); the faces of even id broken (with a residual cohesion) beside intact ones: order 2.0006 / 2.0001 on 1
    rank (8 faces: 6 stuck, 1 slipping, 1 open).
    """
    assert min(taylor["faces_per_rank"]) > 0
    nf = sum(taylor["faces_per_rank"])
    expected = {"lagrange_stick": (nf, 0, 0), "lagrange_slip": (0, nf, 0), "lagrange_open": (0, 0, nf),
                "lagrange_slip_start": (0, nf, 0), "penalty_stick": (nf, 0, 0), "penalty_slip": (0, nf, 0),
                "penalty_open": (0, 0, nf)}
    assert taylor["intact_mixed"]["states"] == {"stick": nf, "slip": 0, "open": 0}
    st = taylor["broken_mixed"]["states"]
    assert st["stick"] >= nf // 2 and st["slip"] > 0 and st["open"] > 0, st
    for name in AFFINE + CURVED + ["cohesive_" + n for n in AFFINE + CURVED] + BREAKING:
        c = taylor[name]
        st = c["states"]
        base = name.removeprefix("cohesive_")
        if base in BREAKING:
            pass                                            # (their states: above)
        elif base in expected:
            assert (st["stick"], st["slip"], st["open"]) == expected[base], name
        else:
            assert min(st.values()) > 0 and sum(st.values()) == nf, name
        if base.startswith("penalty"):
            assert c["states_unchanged"], name              # no branch switch between x and x + h v
        for o in c["order1"]:
            assert 0.98 <= o <= 1.02, (name, c["order1"])
        if base in AFFINE or base == "intact_mixed":
            for e1, e2 in zip(c["e1"], c["e2"]):
                assert e2 <= 1e-9 * e1, (name, c["e1"], c["e2"])
        else:
            for o in c["order2"]:
                assert 1.8 <= o <= 2.2, (name, c["order2"])
            assert c["e2"][-1] <= 1e-2 * c["e1"][-1], name


@pytest.mark.parametrize("ranks", [1, 2])
def test_jacobian_taylor_remainder_at_a_junction(ranks):
    """The Taylor test on two faults crossing (an X junction, 128 faces; 2 ranks: 41 / 87 faces on them): the
    faces' dofs at the junction vertices are the pieces their cells use, in the residual as in the Jacobian.
    Stuck everywhere: affine, remainder round-off (3e-7 against a first-order term of 4e5 and more); slipping
    (with and before a slip increment) and a mix of 43 stick / 43 slip / 42 open faces: order 2.000 measured.
    (The open case's offset opens fa but not fb here, so its faces switch state between x and x + h v.)"""
    out = run_script("jacobian_check.py", ranks=ranks, args=["--junction"])
    assert len(out["faces_per_rank"]) == ranks and min(out["faces_per_rank"]) > 0
    nf = sum(out["faces_per_rank"])
    st = out["lagrange_stick"]
    assert st["states"]["stick"] == nf
    for e1, e2 in zip(st["e1"], st["e2"]):
        assert e2 <= 1e-9 * e1, (st["e1"], st["e2"])
    for name in ("lagrange_slip", "lagrange_slip_start", "lagrange_mixed"):
        c = out[name]
        assert c["states_unchanged"], name
        assert min(c["states"].values()) > 0 if name == "lagrange_mixed" else c["states"]["slip"] == nf, name
        for o in c["order1"]:
            assert 0.98 <= o <= 1.02, (name, c["order1"])
        for o in c["order2"]:
            assert 1.8 <= o <= 2.2, (name, c["order2"])
        assert c["e2"][-1] <= 1e-2 * c["e1"][-1], name


# ---------------------------------------------------------------------------------------------
# Lagrange multipliers against penalty

def jump_error(f):
    return float(np.max(np.hypot(f["opening"], f["slip_magnitude"])))


def test_lagrange_stick_is_exact_and_penalty_error_scales_as_one_over_k(runs):
    """Stick state: the multipliers give no jump; a penalty k (normal = tangential) leaves a jump |t|/k with
    |t| = sqrt(p^2 + tau^2) = 1.077 MPa: measured error x k = 1.086e6 (k = 1e8, error 1.09e-2 m) and 1.078e6 (1e9).
    k = 1e10 is in test_penalty_converges_at_high_stiffness."""
    _, f_lag, _ = runs("stick", 1)
    assert jump_error(f_lag) <= 1e-10
    t_mag = math.hypot(P, TAU_STICK)
    scaled = {}
    for k in (1e8, 1e9):
        s, f, _ = runs("stick", 1, penalty(k))
        assert s["converged"], k
        assert np.all(f["state"] == 0)
        scaled[k] = jump_error(f) * k
        assert scaled[k] == pytest.approx(t_mag, rel=0.1), k
        # penetration p/k and elastic slip tau/k, as in a spring of stiffness k
        assert np.mean(f["opening"]) * k == pytest.approx(-P, rel=0.1)
        assert np.mean(f["slip_magnitude"]) * k == pytest.approx(TAU_STICK, rel=0.1)
    assert scaled[1e9] == pytest.approx(scaled[1e8], rel=0.1)
    assert scaled[1e8] / 1e8 > 1e-4


def test_penalty_converges_at_high_stiffness(runs):
    """A face with zero gap counts as closed: the first Newton step from u = 0 has the contact stiffness."""
    s, f, _ = runs("stick", 1, penalty(1e10), check=False)
    assert s is not None and s["converged"]
    assert s["steps"][-1]["newton_its"] <= 2
    assert jump_error(f) * 1e10 == pytest.approx(math.hypot(P, TAU_STICK), rel=0.1)


def test_penalty_stiffness_keeps_krylov_convergence():
    """Stick-state Jacobian solved by GMRES(30) + ILU(1), rtol 1e-10, 8x4x4 mesh, 1 rank. Penalty faces carry their
    traction as multipliers and their law takes the jump less the penalty's compliance (a perturbed Lagrangian):
    the Jacobian tends to the Lagrange faces' as k grows instead of growing with k. Measured: 19-21
    iterations at k = 1e8 ... 1e11 (Lagrange 21); with the penalty traction a function of the jump alone (no
    multipliers) they were 28, 29, 48, 67 with ILU(0), and Jacobi 172 to 5000. The penalty solutions have
    jump x k = |t|: the 1/k law holds to k = 1e11. One level of fill, because ILU(0)'s fill is the matrix's
    pattern: with the DM's preallocation (explicit zeros across the faces' cells) it took 27-29 iterations for
    both, with exactly the blocks the faces touch (pfault.solver.operator) 120 for the Lagrange faces and 58-119
    for the penalty faces."""
    extra = ["-pfault_box_cells", "8,4,4", "-pfault_bc_xmax_displacement", f"0,0,{DELTA_STICK!r}",
             *shear_tractions(TAU_STICK)]
    ks = [1e8, 1e9, 1e10, 1e11]
    out = run_script("penalty_conditioning.py", args=["-pc", "ilu", "-k", ",".join(f"{k:g}" for k in ks), *extra,
                                                      "-cond_pc_factor_levels", "1"])
    lag = out["lagrange"]["ilu"]
    assert lag["converged"] and lag["ksp_its"] <= 100
    assert lag["max_jump_m"] <= 1e-8
    pen = out["penalty"]
    its = [r["ilu"]["ksp_its"] for r in pen]
    assert all(r["ilu"]["converged"] for r in pen), its
    assert max(its) <= lag["ksp_its"] + 5 and max(its) - min(its) <= 5, (its, lag["ksp_its"])
    for k, r in zip(ks, pen):
        assert r["ilu"]["max_jump_m"] * k == pytest.approx(math.hypot(P, TAU_STICK), rel=0.1), k


# ---------------------------------------------------------------------------------------------
# 1 rank = 2 ranks

def test_one_and_two_ranks_agree_on_fault_fields_and_displacement(runs):
    s1, f1, d1 = runs("slip", 1, FINE)
    s2, f2, d2 = runs("slip", 2, FINE)
    assert s1["converged"] and s2["converged"] and s1["ranks"] == 1 and s2["ranks"] == 2
    assert s1["steps"][-1]["slip"] == s2["steps"][-1]["slip"] == 72
    assert np.array_equal(f1["state"], f2["state"])
    scales = {"traction_normal": "traction_normal", "traction_shear": "traction_shear", "opening": "slip",
              "slip": "slip", "slip_magnitude": "slip"}          # the opening is round-off here: compare to slip
    for name, ref in scales.items():
        assert np.linalg.norm(f1[name] - f2[name]) <= 1e-8 * np.linalg.norm(f1[ref]), name
    p1, _, u1, _ = read_last_step(d1)
    p2, _, u2, _ = read_last_step(d2)
    assert np.array_equal(p1, p2)
    assert np.linalg.norm(u1["displacement"] - u2["displacement"]) <= 1e-8 * np.linalg.norm(u1["displacement"])


def test_bubbles_remove_the_spurious_traction_modes_and_the_inf_sup_constant_stays():
    """P0 tractions on triangles outnumber the P1 jumps: with P1 displacements alone the multiplier Schur
    complement B K^-1 B^T has a null space (18 spurious traction modes on the 6x3x3 two-blocks fault). With the face
    bubbles it has none, and the discrete inf-sup constant (energy norm / h-weighted L2 norm of the traction,
    tests/scripts/inf_sup.py) stays at 0.46 from h to h/3: measured 0.4607, 0.4593, 0.4589, 0.4585."""
    betas = []
    for n in (2, 3, 4, 6):
        out = run_script("inf_sup.py", args=["-pfault_box_cells", f"{2 * n},{n},{n}"])
        assert out["null_modes"] == 0, out
        assert out["null_modes_p1"] == out["multipliers"] - out["jump_dofs"] > 0, out
        if n == 3:
            assert out["null_modes_p1"] == 18
        betas.append(out["beta"])
    assert min(betas) > 0.4 and max(betas) < 0.5, betas
    assert betas[-1] > 0.98 * betas[0], betas       # no decay under refinement


def test_stuck_faces_are_uniform_and_hold(tmp_path):
    """Stick case (uniform exact traction) on the 4x3x3 two-blocks mesh: the tractions are uniform to round-off,
    every face sticks, and no face opens or slips (below 1e-9 m: the mean jump P1 + bubble is held at zero)."""
    extra = ["-pfault_box_cells", "4,3,3", "-pfault_bc_xmax_displacement", f"0,0,{DELTA_STICK!r}",
             *shear_tractions(TAU_STICK), "-snes_max_it", "8", "-pfault_time_max_cuts", "0"]
    proc, s = run_scene(TWO_BLOCKS, tmp_path, extra=extra)
    f = read_fault(tmp_path)
    tn = f["traction_normal"]
    assert s["converged"] and np.all(f["state"] == 0)
    assert np.std(tn) / abs(np.mean(tn)) < 1e-10
    assert np.max(np.abs(f["opening"])) < 1e-9 and np.max(f["slip_magnitude"]) < 1e-9


def test_singular_jacobian_fails_fast_and_says_so(tmp_path, ranks=2):
    """A geostatic start for the two blocks, whose right block hangs from its sides (nothing holds it up), with
    the water table 0.5 m above their top: the water pressure pulls every fault face open at step 0 (at the water
    table of the top, 0 m, one face stays closed by 5 Pa of effective stress since the initial stress has the
    face bubbles' strain, and the run converges), and with every face open the right block is
    held in x by nothing, so each Jacobian of step 1 is singular. Each linear solve on such factors stops after
    SINGULAR_MAX_IT Krylov iterations (it ran to -ksp_max_it, 10000, in every one of the 8 sub-step attempts),
    and the step's line names the cause. (On one rank MUMPS's factorisation flags no null pivot here, INFOG(28) =
    0, and FGMRES stops on its divergence test, about 285 iterations per attempt.)"""
    from pfault.solver.policy import SINGULAR_MAX_IT
    proc, s = run_scene(TWO_BLOCKS, tmp_path / "out", ranks=ranks,
                        extra=["-pfault_geostatic", "true", "-pfault_water_table", "0.5"], check=False)
    assert proc.returncode == 3 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    step = s["steps"][-1]
    assert not step["converged"] and step["null_pivots"] > 0, step
    # each of the 4 attempts (the step, then 2, 4, 8 sub-steps, each failing in its first) counts 1 Newton
    # iteration, its elastic trial, and solves twice: the trial and the first Newton step
    assert step["ksp_its"] <= SINGULAR_MAX_IT * step["newton_its"] * 2, step
    assert "singular Jacobian: " in proc.stdout and "null pivots" in proc.stdout


ITERATIVE = ("-pfault_solver", "iterative", "-ksp_rtol", "1e-12")


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case", ["stick", "slip", "open", "cohesion", "penalty", "slip_gamg"])
def test_iterative_solver_reaches_the_direct_solution(runs, case, ranks):
    """-pfault_solver iterative (FGMRES, Schur fieldsplit with the multipliers eliminated first, BoomerAMG on
    the augmented displacement) gives the MUMPS answer (1e-8) in every state: stuck (the right block is held in
    x only through the fault), slipping, open, with cohesion, and with penalty faces (no multiplier field), with
    the same Newton iterations, in at most 40 Krylov iterations per Newton iteration (rtol 1e-12). GAMG chosen
    for the displacement on the command line replaces BoomerAMG without the file's BoomerAMG options (no
    unused-option error)."""
    extra = penalty(1e9) if case == "penalty" else ()
    base = {"penalty": "stick", "slip_gamg": "slip"}.get(case, case)
    direct, fd, _ = runs(base, ranks, extra)
    solver = (*ITERATIVE, "-fieldsplit_displacement_pc_type", "gamg") if case == "slip_gamg" else ITERATIVE
    it, fi, _ = runs(base, ranks, (*extra, *solver))
    assert it["converged"]
    last, ref = it["steps"][-1], direct["steps"][-1]
    assert last["newton_its"] == ref["newton_its"]
    assert last["newton_its"] < last["ksp_its"]
    if case != "slip_gamg":
        assert last["ksp_its"] <= 40 * last["newton_its"], last
    assert np.array_equal(fi["state"], fd["state"])
    for key in ("slip_magnitude", "opening", "traction_normal"):
        scale = max(np.abs(fd[key]).max(), 1e-3 if key != "traction_normal" else P)
        assert np.abs(fi[key] - fd[key]).max() <= 1e-8 * scale, key


# ---------------------------------------------------------------------------------------------
# time stepping: proportional loading, and loading-unloading-reloading

RAMP = [a for s in ("xmax", "top", "bottom") for a in (f"-pfault_bc_{s}_history", "0:0,1:1")]


@pytest.mark.parametrize("ranks", [1, 2])
def test_proportional_loading_gives_the_same_answer_in_1_10_and_40_steps(runs, ranks):
    """All loads of the slip case ramp linearly, so the solution at time t is t times the final one: slip
    t (delta - L tau_L / G) at every step, and the same final slip (1e-8) whatever the number of steps; every step
    converges without sub-steps, each in a few Newton iterations."""
    exact = DELTA - L * P * TAN_PHI / G
    for n in (1, 10, 40):
        s, f, _ = runs("slip", ranks, [*RAMP, "-pfault_time_steps", str(n)])
        assert s["converged"], n
        steps = s["steps"][-n:]
        for k, st in enumerate(steps, start=1):
            assert abs(st["max_fault_slip_m"] - k / n * exact) <= 1e-8 * exact, (n, k, st["max_fault_slip_m"])
            assert st.get("substeps", 1) == 1 and st["newton_its"] <= 8, (n, k, st)
        assert rel(f["slip_magnitude"], exact) <= 1e-8


# normal displacement of the right face (x) scaled by a history: pressed (-1 mm), pulled open (+10 mm), pressed
# again, pulled again; no shear load
CYCLE = ["-pfault_bc_xmax_components", "x,z", "-pfault_bc_xmax_displacement", "1e-3,0,0", "-pfault_bc_xmax_traction",
         "0,0,0", *shear_tractions(0.0, 0.0), "-pfault_bc_xmax_history", "0:0,1:-1,2:10,3:-1,4:10",
         "-pfault_time_end", "4", "-pfault_time_steps", "8"]


@pytest.mark.parametrize("ranks", [1, 2])
def test_loading_unloading_reloading_closes_and_reopens_the_fault(runs, ranks):
    """The fault is pressed shut, pulled open, pressed shut again and reopened: every step converges without
    sub-steps in a few Newton iterations; while pulled the right block translates freely (opening = the pull,
    exactly), while pressed every face is closed and compressed and the opening is zero."""
    s, _, _ = runs("cycle", ranks, CYCLE)
    n = s["mesh"]["fault_faces"]
    steps = [st for st in s["steps"] if st["time_s"] > 0]
    assert s["converged"] and len(steps) == 8
    for st in steps:
        assert st.get("substeps", 1) == 1 and st["newton_its"] <= 6, st
    scale = {0.5: -0.5, 1.0: -1.0, 1.5: 4.5, 2.0: 10.0, 2.5: 4.5, 3.0: -1.0, 3.5: 4.5, 4.0: 10.0}
    for st in steps:
        pull = scale[st["time_s"]] * 1e-3
        if pull > 0:
            assert st["open"] == n, st
            assert abs(st["max_fault_opening_m"] - pull) <= 1e-9, st
        else:
            assert st["open"] == 0 and st["stick"] == n, st
            # closed: no face is open, so no opening is reported
            assert st["max_fault_opening_m"] == 0.0, st


@pytest.mark.parametrize("method", ["lagrange", "penalty"])
def test_a_step_at_zero_load_after_a_recovery_converges(tmp_path, method):
    """Geostatic fissure box: 20 m of drawdown in a year, recovered in the next (the faces slipped and keep a
    permanent offset), then a year at zero drawdown. The last step starts from the converged state: its load
    vector is zero and its residual round-off of the internal forces. Its tolerance scales with those forces
    and the gravity load, not with the zero load: one Newton iteration. Scaled by the load alone it ran to
    -snes_max_it (51 iterations, not converged)."""
    out = tmp_path / method
    _, s = run_scene(FISSURE_BOX, out, ranks=2,
                     extra=["-pfault_geostatic", "true", "-pfault_fault_fissure_method", method,
                            "-pfault_material_sand_head_drawdown", "0:0,1*year:20,2*year:0,3*year:0",
                            "-pfault_time_steps", "3", "-pfault_time_end", "3*year", "-pfault_time_max_cuts", "0"])
    assert s["converged"]
    steps = [st for st in s["steps"] if st["time_s"] > 0]
    assert steps[0]["slip"] > 0 and steps[1]["max_fault_slip_m"] > 1e-3     # a permanent offset
    assert steps[2]["newton_its"] <= 2 and steps[2].get("substeps", 1) == 1
    assert steps[2]["max_fault_slip_m"] == pytest.approx(steps[1]["max_fault_slip_m"], rel=1e-8)
