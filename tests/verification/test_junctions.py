"""Patch tests of fault junctions: a box cut by two vertical faults, x = 2 m (fa) and y = 2 m (fb), that cross
(X junction) or where fb ends on fa (T junction), under a load whose exact solution is a uniform stress with
principal axes along the faults' normals (sigma_xx = -a, sigma_yy = -b, sigma_zz = -c, no shear on either plane).

Box [0, 4] x [0, 4] x [-2, 0] m, 4 x 4 x 4 hexahedra (384 tetrahedra), E = 10 MPa, nu = 0.25. Rollers on xmin,
ymin and bottom; tractions (-a, 0, 0) on xmax, (0, -b, 0) on ymax, (0, 0, -c) on top. The faults reach down to
z = -1.5 m (their lower edges are tips inside the box), so the junction line x = y = 2 m runs from the land
surface to the tips and its vertices fall into four (X) or three (T) pieces, each with its own dofs. Exact:
u = (e_xx x, e_yy y, e_zz (z + 2)) at every copy of every vertex, fa's faces carry t_N = -a, fb's t_N = -b,
no shear traction, no jump.
- friction (c = 0, phi = 30 deg): every face sticks;
- frictionless faults (c = 0, phi = 0) under another load: the shear limit is zero, and the exact stress puts no
  shear on the faults, so again nothing slides;
- an open T junction: fa cuts the box through (its whole height and width), fb runs from xmin to fa; xmax is
  pulled by d along x (u_x = d, tangential traction zero), so fa opens traction-free, the stress is uniform
  with sigma_xx = 0 in both blocks and fb's faces stay closed under -b. The right block moves by the jump
  J = d - e_xx L_x: fa's opening is J on every face, fb's jump is zero.
Measured on 1 and 2 ranks (a single Newton iterate, LU): displacement within 5.2e-15 of the largest at every
vertex copy, stress and face tractions within 1.1e-14 of the largest load, jumps below 3e-16 m (J = 0.025 m)."""

import numpy as np
import pytest

from conftest import read_last_step, run_scene, run_script
from pfault.faults import contact as ct
from pfault.post import rundir

E, NU = 10.0e6, 0.25
LX, LY, LZ = 4.0, 4.0, 2.0
XF, YF = 2.0, 2.0                                   # fa: x = XF, fb: y = YF
TOL_U = 1e-11                                       # of the largest displacement
TOL_T = 1e-11                                       # of the largest load
TOL_JUMP = 1e-12                                    # m (displacements are ~0.1 m)

SCENE = """# junction patch test (tests/verification/test_junctions.py)
-pfault_scene junction_patch
-pfault_mesh_generator box
-pfault_box_size 4,4,2
-pfault_box_cells 4,4,4
-pfault_box_materials rock
-pfault_material_rock_young_modulus 10*MPa
-pfault_material_rock_poisson_ratio 0.25
-pfault_faults fa,fb
-pfault_fault_fa_cohesion 0
-pfault_fault_fb_cohesion 0
-pfault_bc_xmin_type roller
-pfault_bc_ymin_type roller
-pfault_bc_bottom_type roller
-pfault_bc_ymax_type traction
-pfault_bc_top_type traction
-pfault_time_end 1
-pfault_time_steps 1
-pfault_solver mumps
"""

PLANES = {"X": "fa:x:2:0:4:-1.5:0,fb:y:2:0:4:-1.5:0",
          "T": "fa:x:2:0:4:-1.5:0,fb:y:2:0:2:-1.5:0",
          "open_T": "fa:x:2,fb:y:2:0:2:-2:0"}
# (a, b, c) in Pa, friction angle in degrees
LOADS = {"friction": (1.0e6, 0.5e6, 0.25e6, 30.0), "frictionless": (0.4e6, 1.2e6, 0.6e6, 0.0)}
OPEN_D = 0.1                                        # m, u_x prescribed on xmax in the open case (J = 0.025 m)
OPEN_LOAD = (0.0, 0.5e6, 0.25e6, 30.0)


def strains(a, b, c):
    """e_xx, e_yy, e_zz of the uniform stress diag(-a, -b, -c)."""
    s = np.array([-a, -b, -c])
    return (s - NU * (s.sum() - s)) / E


def options(case, load, ranks):
    a, b, c, phi = load
    extra = ["-pfault_box_fault_planes", PLANES[case],
             "-pfault_fault_fa_friction_angle", repr(phi), "-pfault_fault_fb_friction_angle", repr(phi),
             "-pfault_bc_ymax_traction", f"0,{-b!r},0", "-pfault_bc_top_traction", f"0,0,{-c!r}"]
    if case == "open_T":
        extra += ["-pfault_bc_xmax_type", "displacement", "-pfault_bc_xmax_components", "x",
                  "-pfault_bc_xmax_displacement", f"{OPEN_D!r},0,0"]
    else:
        extra += ["-pfault_bc_xmax_type", "traction", "-pfault_bc_xmax_traction", f"{-a!r},0,0"]
    return extra


def solve(tmp_path, case, load, ranks):
    scene = tmp_path / "junction.opts"
    scene.write_text(SCENE)
    _, summary = run_scene(str(scene), tmp_path / "out", ranks=ranks, extra=options(case, load, ranks))
    assert summary["converged"], case
    points, _, point_data, cell_data = read_last_step(tmp_path / "out")
    fault = rundir.read_fault(str(tmp_path / "out"))
    return points, np.asarray(point_data["displacement"]), np.asarray(cell_data["stress"][0]), fault


def junction_pieces(points):
    """Number of copies of each vertex on the junction line x = XF, y = YF."""
    on = np.isclose(points[:, 0], XF) & np.isclose(points[:, 1], YF)
    _, counts = np.unique(points[on].round(9), axis=0, return_counts=True)
    return counts


def fault_faces(fault):
    """fa's and fb's faces (masks) and whether each face touches the junction line."""
    names = fault.cell_data["fault"]
    tri = fault.points[fault.cells]
    on_line = (np.isclose(tri[:, :, 0], XF) & np.isclose(tri[:, :, 1], YF)).any(axis=1)
    fa = np.all(np.isclose(tri[:, :, 0], XF), axis=1)
    fb = np.all(np.isclose(tri[:, :, 1], YF), axis=1)
    assert np.all(fa ^ fb) and len(np.unique(names[fa])) == 1 and len(np.unique(names[fb])) == 1
    return fa, fb, on_line


def check_uniform(points, u, stress, fault, load, jump_x, friction):
    a, b, c, _ = load
    exx, eyy, ezz = strains(*(a if jump_x == 0.0 else 0.0, b, c))
    exact = np.column_stack([exx * points[:, 0], eyy * points[:, 1], ezz * (points[:, 2] + LZ)])
    # the right block (x > XF, and fa's plus-side copies at x = XF) moves by jump_x
    plus = points[:, 0] > XF + 1e-9
    exact[plus, 0] += jump_x
    scale = np.abs(exact).max()
    err_u = np.abs(u - exact)
    # the copies at x = XF are on either side of fa: each is held to the nearer of the two exact values, and
    # where fa's copies meet, the spread of their u_x is the jump
    on_fa = np.isclose(points[:, 0], XF)
    err_u[on_fa, 0] = np.minimum(err_u[on_fa, 0], np.abs(u[on_fa, 0] - exact[on_fa, 0] - jump_x))
    if jump_x > 0.0:
        _, group = np.unique(points[on_fa].round(9), axis=0, return_inverse=True)
        ux = u[on_fa, 0]
        spread = np.array([np.ptp(ux[group.ravel() == g]) for g in range(group.max() + 1)])
        err_u[on_fa, 0] = np.maximum(err_u[on_fa, 0], np.abs(spread - jump_x)[group.ravel()])
    load_scale = max(a, b, c)
    sig = np.diag([-a if jump_x == 0.0 else 0.0, -b, -c]).ravel()
    err_s = np.abs(stress - sig).max() / load_scale
    fa, fb, on_line = fault_faces(fault)
    f = fault.cell_data
    tn_exact = np.where(fa, -a if jump_x == 0.0 else 0.0, -b)
    err_tn = np.abs(f["traction_normal"] - tn_exact).max() / load_scale
    err_ts = np.abs(f["traction_shear"]).max() / load_scale
    open_exact = np.where(fa, jump_x, 0.0)
    err_open = np.abs(f["opening"] - open_exact).max()
    err_slip = np.abs(f["slip"]).max()
    figures = dict(u=err_u.max() / scale, stress=err_s, tn=err_tn, ts=err_ts, opening=err_open, slip=err_slip,
                   faces=(int(fa.sum()), int(fb.sum()), int(on_line.sum())))
    assert figures["u"] < TOL_U, figures
    assert err_s < TOL_T and err_tn < TOL_T and err_ts < TOL_T, figures
    assert err_open < TOL_JUMP and err_slip < TOL_JUMP, figures
    assert on_line.sum() > 0, figures
    state = f["state"]
    if jump_x > 0.0:
        assert np.all(state[fa] == ct.OPEN) and np.all(state[fb] != ct.OPEN), figures
    elif friction:
        assert np.all(state == ct.STICK), figures
    else:
        assert np.all(state != ct.OPEN), figures
    return figures


@pytest.mark.parametrize("case,total", [("X", 48), ("T", 36), ("open_T", 48)])
def test_fault_faces_on_both_ranks(tmp_path, case, total):
    """The 2-rank runs below split the faults between the ranks (measured: 29 / 19, 27 / 9 and 35 / 13 faces)."""
    scene = tmp_path / "junction.opts"
    scene.write_text(SCENE)
    out = run_script("fault_partition.py", ranks=2, args=["--scene", str(scene), "-pfault_box_fault_planes",
                                                          PLANES[case]])
    assert out["fault_faces"] == sum(out["faces_per_rank"]) == total, out
    assert min(out["faces_per_rank"]) > 0, out["faces_per_rank"]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("load", list(LOADS))
@pytest.mark.parametrize("case", ["X", "T"])
def test_closed_junction_carries_the_uniform_stress(tmp_path, case, load, ranks):
    points, u, stress, fault = solve(tmp_path, case, LOADS[load], ranks)
    pieces = junction_pieces(points)
    # the vertices of the junction line at z = 0, -0.5, -1 m: four pieces (X) or three (T); the tip vertex at
    # z = -1.5 m and the one below it at -2 m are one each
    assert sorted(pieces.tolist()) == [1, 1] + [4 if case == "X" else 3] * 3, pieces
    check_uniform(points, u, stress, fault, LOADS[load], 0.0, friction=LOADS[load][3] > 0)


@pytest.mark.parametrize("ranks", [1, 2])
def test_open_t_junction_moves_the_blocks_apart_rigidly(tmp_path, ranks):
    points, u, stress, fault = solve(tmp_path, "open_T", OPEN_LOAD, ranks)
    pieces = junction_pieces(points)
    assert sorted(pieces.tolist()) == [3] * 5, pieces
    exx = strains(0.0, *OPEN_LOAD[1:3])[0]
    check_uniform(points, u, stress, fault, OPEN_LOAD, OPEN_D - exx * LX, friction=True)
