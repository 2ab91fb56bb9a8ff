#!/usr/bin/env python
"""Frictional crack in compression and shear (plane strain): pfault's slip against the closed form, beside GetFEM's
P1 Alart-Curnier contact on the same meshes.

    .venv/bin/python benchmarks/frictional_crack.py [--levels 4 8 16 32] [--L 10] [--ranks 1]
                                                    [--no-getfem | --getfem nodal integral-p0 integral-p1]
                                                    [--out runs/frictional_crack]

The problem is config/frictional_crack.opts: a cohesionless crack of half-length a = 1 m (friction angle 30 degrees)
under sigma_n = 10 MPa and tau = 10 MPa, whose exact slip is s(x) = 4 (1-nu^2)/E (tau - f sigma_n) sqrt(a^2 - x^2).
For each level n (element size h = a/n on the crack; tests/scripts/frictional_crack_mesh.py) the gmsh mesh is made
once and both codes read it:

- pfault: ``python -m pfault config/frictional_crack.opts`` (P1 tetrahedra with face bubbles, P0 tractions,
  semismooth Newton), under mpirun for --ranks > 1;
- GetFEM (Debian's python3-getfem, 5.4): the same tetrahedra with the crack's vertices split, P1 displacements,
  and the crack held by the basic contact brick (``Model.add_basic_contact_brick``: nodal multipliers, Coulomb
  friction, the non-symmetric Alart-Curnier augmented Lagrangian, augmented_version 1, GetFEM's Newton) whose
  matrices B_N, B_T are the jumps of the split vertex pairs. GetFEM's own nodal contact brick
  (``add_nodal_contact_between_nonmatching_meshes_brick``) computes B_N, B_T, the gap and alpha by projection and
  calls this same brick (its documentation); here the pairs are known, alpha = 1 (it scales the augmentation
  r = E h only, not the solution). ``--getfem integral-p0 integral-p1`` adds GetFEM's integral Alart-Curnier brick
  (``add_integral_contact_between_nonmatching_meshes_brick``, the one displacement field on both sides of the
  crack, the contact and friction stress P0 or P1 on the lower side's faces).
  The same boundary conditions: plane-strain rollers (u_y = 0 on both faces of the slab, by multipliers), clamped
  bottom, the uniform stress's tractions on the top and the sides.

Both are measured alike: the slip of each crack triangle (for pfault its face average, as fault.h5 gives it; for
GetFEM the mean of the triangle's three vertex jumps, i.e. the face average of the P1 jump) against the exact slip
averaged over that triangle: the L2 error over the crack relative to the exact slip's L2 norm, and the largest face
error relative to s(0). One table row per level and code: h, crack faces, the errors, the observed rates against
the previous level, the potency's error (the slip's integral; its change with --L measures the far boundary's
share), Newton iterations and wall time (pfault: its summary's total; GetFEM: from reading the mesh to
the solution). A JSON line with every figure ends the output.
"""
import argparse
import contextlib
import json
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
sys.path.insert(0, os.path.join(REPO, "tests", "scripts"))
from frictional_crack_mesh import make_crack_mesh, read_pfault_slip, slip_errors  # noqa: E402
from pfault.post.rundir import read_summary  # noqa: E402
from pfault.tools.runs import run_captured  # noqa: E402

SCENE = os.path.join(REPO, "config", "frictional_crack.opts")
# the scene's values (config/frictional_crack.opts)
A, YOUNG, NU = 1.0, 10e9, 0.25
SIGMA_N, TAU, FRICTION = 10e6, 10e6, np.tan(np.radians(30.0))
STRESS_DROP = TAU - FRICTION * SIGMA_N
NEWTON_RTOL = 1e-10
GETFEM_CONTACTS = ("nodal", "integral-p0", "integral-p1")


def run_pfault(mesh, out, ranks):
    t0 = time.perf_counter()
    proc = run_captured(["-m", "pfault", SCENE, "-pfault_mesh_file", mesh, "-pfault_output_dir", out,
                         "-pfault_figures", "false"], ranks, cwd=REPO)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"pfault exited {proc.returncode}:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    summary = read_summary(out)
    tri_x, slip, fields = read_pfault_slip(out)
    e = slip_errors(tri_x, slip, A, YOUNG, NU, STRESS_DROP)
    e.update(newton=int(summary["steps"][-1]["newton_its"]),
             wall_s=float(summary["wall_s"]["total"]), run_s=wall,
             states=np.bincount(fields["state"], minlength=3).tolist(),
             largest_opening=float(np.abs(fields["opening"]).max()),
             friction_ratio=float(np.max(np.linalg.norm(fields["traction_shear"], axis=1)
                                         / np.abs(fields["traction_normal"]))))
    return e


@contextlib.contextmanager
def _quiet_stdout():
    """File descriptor 1 to /dev/null (GetFEM writes an empty line to it while the mesh is built)."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _split_crack(points, tets, crack_tris, L):
    """Duplicate the crack's vertices (not those of its tips) for the tetrahedra above it (centroid z > 0);
    return the new points, tetrahedra and the pairs (lower, upper) of split vertices."""
    crack_nodes = np.unique(crack_tris)
    inner = crack_nodes[np.abs(points[crack_nodes, 0]) < A - 1e-9 * L]
    upper_id = np.full(len(points), -1)
    upper_id[inner] = len(points) + np.arange(len(inner))
    above = points[tets].mean(axis=1)[:, 2] > 0.0
    new_tets = tets.copy()
    sub = new_tets[above]
    moved = upper_id[sub] >= 0
    sub[moved] = upper_id[sub[moved]]
    new_tets[above] = sub
    return np.vstack([points, points[inner]]), new_tets, np.column_stack([inner, upper_id[inner]])


def _getfem_mesh(gf, mesh_path):
    """The gmsh mesh as a GetFEM mesh with the crack's vertices split; its boundary regions (bottom, top, xmin,
    xmax: 1-4), the original points, the crack triangles and the split pairs."""
    import meshio
    msh = meshio.read(mesh_path)
    points = msh.points
    tets = np.concatenate([c.data for c in msh.cells if c.type == "tetra"])
    L = float(points[:, 0].max())
    crack_tag = msh.field_data["crack"][0]
    crack_tris = np.concatenate([c.data[msh.cell_data["gmsh:physical"][i] == crack_tag]
                                 for i, c in enumerate(msh.cells) if c.type == "triangle"])
    pts, new_tets, pairs = _split_crack(points, tets, crack_tris, L)
    # GetFEM merges points closer than ~1e-8: the upper copies are built lifted, then put back in place
    lifted = pts.copy()
    lifted[len(points):, 2] += 1e-3 * A
    m = gf.Mesh("ptND", lifted.T, new_tets.T)
    if m.nbpts() != len(pts) or not np.allclose(m.pts().T, lifted):
        raise RuntimeError("GetFEM renumbered the mesh's points")
    m.set_pts(pts.T)
    eps, big = 1e-6 * L, 2.0 * L
    boxes = {"bottom": ([-big, -big, -L - eps], [big, big, -L + eps]),
             "top": ([-big, -big, L - eps], [big, big, L + eps]),
             "xmin": ([-L - eps, -big, -big], [-L + eps, big, big]),
             "xmax": ([L - eps, -big, -big], [L + eps, big, big])}
    rid = {}
    for k, (name, (lo, hi)) in enumerate(boxes.items()):
        rid[name] = k + 1
        m.set_region(rid[name], m.outer_faces_in_box(lo, hi))
    return {"mesh": m, "regions": rid, "L": L, "points": points, "pts": pts, "crack_tris": crack_tris, "pairs": pairs}


def _node_dofs(mf, m, npts):
    """(points, 3) dofs of a P1 vector field: the dofs of a convex follow its vertices, three components each."""
    dofs, idx = mf.basic_dof_from_cvid()
    cv_pts, cv_idx = m.pid_from_cvid()
    node_dof = np.full((npts, 3), -1)
    for k in range(4):
        node_dof[cv_pts[cv_idx[:-1] + k]] = dofs[idx[:-1] + 3 * k][:, None] + np.arange(3)
    if not np.array_equal(node_dof, node_dof[:, :1] + np.arange(3)) or node_dof.max() != mf.nbdof() - 1:
        raise RuntimeError("unexpected GetFEM dof numbering")
    return node_dof


def _contact_matrices(gf, lo_d, up_d, ndof):
    """B_N u = -(u_z+ - u_z-) <= 0 and B_T u = (u_x+ - u_x-, u_y+ - u_y-) of the split pairs' dofs, as Spmat."""
    import scipy.sparse as sp
    nc = len(lo_d)
    rows, one = np.arange(nc), np.ones(nc)
    bn = sp.coo_matrix((np.r_[one, -one], (np.r_[rows, rows], np.r_[lo_d[:, 2], up_d[:, 2]])), shape=(nc, ndof))
    bt = sp.coo_matrix((np.r_[one, -one, one, -one],
                        (np.r_[2 * rows, 2 * rows, 2 * rows + 1, 2 * rows + 1],
                         np.r_[up_d[:, 0], lo_d[:, 0], up_d[:, 1], lo_d[:, 1]])), shape=(2 * nc, ndof))
    mats = []
    for mat in (bn, bt):
        gmat = gf.Spmat("empty", *mat.shape)
        for i, j, v in zip(mat.row.tolist(), mat.col.tolist(), mat.data.tolist()):
            gmat[i, j] = v
        mats.append(gmat)
    return mats


def _nodal_contact(gf, md, g, lo_d, up_d, ndof):
    """The basic contact brick on the split pairs: nodal multipliers, non-symmetric Alart-Curnier."""
    nc = len(lo_d)
    bn, bt = _contact_matrices(gf, lo_d, up_d, ndof)
    md.add_variable("lambda_n", nc)
    md.add_variable("lambda_t", 2 * nc)
    # augmentation: a vertex's stiffness, E (here 1) times the crack's largest element size
    h = float(np.max(np.diff(np.sort(g["points"][np.unique(g["crack_tris"]), 0]))))
    md.add_initialized_data("r", [h])
    md.add_initialized_data("friction", np.full(nc, FRICTION))
    md.add_initialized_data("gap", np.zeros(nc))
    md.add_initialized_data("alpha", np.ones(nc))
    md.add_basic_contact_brick("u", "lambda_n", "lambda_t", "r", bn, bt, "friction", "gap", "alpha", 1)


def _integral_contact(gf, md, g, degree):
    """GetFEM's integral Alart-Curnier brick between the crack's two sides (one displacement field on both), its
    multiplier (contact and friction stress) P0 or P1 on the lower side's faces."""
    m, L = g["mesh"], g["L"]
    eps = 1e-6 * L
    faces = m.outer_faces_in_box([-A - eps, -2 * L, -eps], [A + eps, 2 * L, eps])
    cv_pts, idx = m.pid_from_cvid(faces[0])
    above = np.add.reduceat(g["pts"][cv_pts, 2], idx[:-1]) > 0.0
    m.set_region(11, faces[:, ~above])
    m.set_region(12, faces[:, above])
    mfl = gf.MeshFem(m, 3)
    if degree == 0:
        mfl.set_classical_discontinuous_fem(0)
    else:
        mfl.set_classical_fem(1)
    md.add_filtered_fem_variable("lambda_c", mfl, 11)
    md.add_initialized_data("r", [1.0])          # E, in the units of E
    md.add_initialized_data("friction", [FRICTION])
    md.add_integral_contact_between_nonmatching_meshes_brick(g["mim"], "u", "u", "lambda_c", "r", "friction", 11, 12, 1)


def run_getfem(mesh_path, contact="nodal"):
    """Solve the scene with GetFEM on the mesh at ``mesh_path`` with its nodal Alart-Curnier contact (``contact``
    "nodal") or its integral one with P0 or P1 multipliers ("integral-p0", "integral-p1"); the slip errors, Newton
    iterations and wall."""
    import getfem as gf
    gf.util_trace_level(0)
    gf.util_warning_level(0)
    t0 = time.perf_counter()
    with _quiet_stdout():
        g = _getfem_mesh(gf, mesh_path)
    m, rid, pts, pairs, L = g["mesh"], g["regions"], g["pts"], g["pairs"], g["L"]
    mf = gf.MeshFem(m, 3)
    mf.set_classical_fem(1)
    mim = gf.MeshIm(m, gf.Integ("IM_TETRAHEDRON(2)"))
    g["mim"] = mim
    node_dof = _node_dofs(mf, m, len(pts))
    ndof = mf.nbdof()

    # stresses in units of E (the displacements stay in metres), so that the multipliers' equations (lengths)
    # and the displacements' (forces) are of one scale in GetFEM's Newton residual
    sn, tau = SIGMA_N / YOUNG, TAU / YOUNG
    sxx = -NU / (1 - NU) * sn
    md = gf.Model("real")
    md.add_fem_variable("u", mf)
    md.add_initialized_data("lambda", [NU / ((1 + NU) * (1 - 2 * NU))])
    md.add_initialized_data("mu", [1.0 / (2 * (1 + NU))])
    md.add_isotropic_linearized_elasticity_brick(mim, "u", "lambda", "mu")
    md.add_Dirichlet_condition_with_simplification("u", rid["bottom"])
    # plane strain: every vertex lies on one of the slab's faces, so the rollers are u_y = 0 at every vertex not
    # clamped, by one multiplier each (B u = 0 with B the rows of the identity at those dofs)
    free_y = node_dof[np.abs(pts[:, 2] + L) > 1e-6 * L, 1]
    rollers = gf.Spmat("copy", gf.Spmat("identity", ndof), free_y.tolist(), list(range(ndof)))
    md.add_variable("mult_y", len(free_y))
    md.add_constraint_with_multipliers("u", "mult_y", rollers, np.zeros(len(free_y)))
    md.add_source_term_brick(mim, "u", f"[{tau!r}, 0, {-sn!r}]", rid["top"])
    md.add_source_term_brick(mim, "u", f"[{sxx!r}, 0, {tau!r}]", rid["xmax"])
    md.add_source_term_brick(mim, "u", f"[{-sxx!r}, 0, {-tau!r}]", rid["xmin"])

    lo_d, up_d = node_dof[pairs[:, 0]], node_dof[pairs[:, 1]]
    if contact == "nodal":
        _nodal_contact(gf, md, g, lo_d, up_d, ndof)
    else:
        _integral_contact(gf, md, g, 0 if contact == "integral-p0" else 1)
    # GetFEM's Newton stops when its scaled residual (0.94 at the first iterate here) is below NEWTON_RTOL;
    # round-off leaves 3e-13 to 1e-11 on these meshes. MUMPS: the "superlu" linear solver of Debian's GetFEM 5.4.2
    # ends in a segmentation fault on this model
    nit, converged = md.solve("max_res", NEWTON_RTOL, "max_iter", 50, "lsolver", "mumps")
    wall = time.perf_counter() - t0
    if not converged:
        raise RuntimeError(f"GetFEM's Newton did not converge in {nit} iterations on {mesh_path}")
    return _getfem_errors(md, g, lo_d, up_d, nit, wall, contact == "nodal")


def _getfem_errors(md, g, lo_d, up_d, nit, wall, nodal):
    """Slip errors of the face averages of the P1 jump, and the contact's checks."""
    u = md.variable("u")
    jump = u[up_d] - u[lo_d]                              # (pairs, 3)
    node_jump = np.zeros((len(g["points"]), 3))          # zero at the tips
    node_jump[g["pairs"][:, 0]] = jump
    face_slip = node_jump[g["crack_tris"], 0].mean(axis=1)
    face_slip *= np.sign(np.sum(face_slip))
    e = slip_errors(g["points"][g["crack_tris"]], face_slip, A, YOUNG, NU, STRESS_DROP)
    e.update(newton=int(nit), wall_s=wall, pairs=len(jump), largest_opening=float(np.abs(jump[:, 2]).max()),
             stuck_pairs=int(np.sum(np.abs(jump[:, 0]) < 1e-9 * e["s0"])))
    if nodal:
        ln, lt = md.variable("lambda_n"), md.variable("lambda_t").reshape(-1, 2)
        e["friction_ratio"] = float(np.max(np.linalg.norm(lt, axis=1) / np.abs(ln)))
    return e


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--levels", type=int, nargs="+", default=[4, 8, 16, 32])
    p.add_argument("--L", type=float, default=10.0, help="half-side of the section (m)")
    p.add_argument("--ranks", type=int, default=1, help="pfault's MPI ranks")
    p.add_argument("--no-getfem", action="store_true", help="pfault only")
    p.add_argument("--getfem", nargs="+", choices=GETFEM_CONTACTS, default=["nodal"],
                   help="GetFEM's contact bricks to run (default: nodal)")
    p.add_argument("--out", default=os.path.join(REPO, "runs", "frictional_crack"))
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    if not args.no_getfem:
        try:
            import getfem  # noqa: F401
        except ImportError as exc:
            sys.exit(f"frictional_crack.py: GetFEM cannot be imported ({exc}): install Debian's python3-getfem "
                     "(the venv sees the system's packages), or run with --no-getfem")
    codes = ["pfault"] + ([] if args.no_getfem else [f"getfem-{c}" for c in args.getfem])
    rows = {c: [] for c in codes}
    s0 = 4 * (1 - NU ** 2) / YOUNG * STRESS_DROP * A
    print(f"frictional crack a = {A:g} m, L = {args.L:g} m, s(0) = {1e3 * s0:.4f} mm; pfault on {args.ranks} "
          "rank(s): slip errors of the crack faces against the face averages of s(x)")
    print(f"{'code':>18} {'n':>3} {'h':>7} {'tets':>7} {'faces':>5} {'L2 err':>7} {'max err':>7} {'rate L2':>7} "
          f"{'rate max':>8} {'potency':>8} {'newton':>6} {'wall s':>7}")
    for n in args.levels:
        mesh = make_crack_mesh(os.path.join(args.out, f"crack{n}.msh"), A, args.L, n)
        for code in codes:
            if code == "pfault":
                e = run_pfault(mesh["path"], os.path.join(args.out, f"n{n}_r{args.ranks}"), args.ranks)
            else:
                e = run_getfem(mesh["path"], code[len("getfem-"):])
            e.update(n=n, h=mesh["h"], tets=mesh["tets"])
            rate = ["", ""]
            if rows[code]:
                prev = rows[code][-1]
                dh = np.log(prev["h"] / e["h"])
                e["rate_l2"] = float(np.log(prev["l2_error"] / e["l2_error"]) / dh)
                e["rate_max"] = float(np.log(prev["max_error"] / e["max_error"]) / dh)
                rate = [f"{e['rate_l2']:.2f}", f"{e['rate_max']:.2f}"]
            rows[code].append(e)
            print(f"{code:>18} {n:>3} {e['h']:>7.4f} {e['tets']:>7} {e['faces']:>5} {100 * e['l2_error']:>6.2f}% "
                  f"{100 * e['max_error']:>6.2f}% {rate[0]:>7} {rate[1]:>8} {100 * e['potency_error']:>+7.2f}% "
                  f"{e['newton']!s:>6} {e['wall_s']:>7.2f}",
                  flush=True)
    print(json.dumps({c: [{k: v for k, v in r.items()} for r in rs] for c, rs in rows.items()}))


if __name__ == "__main__":
    main()
