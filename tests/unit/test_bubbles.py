"""Face bubbles and their static condensation (pfault.faults.bubbles) on a patch of two tetrahedra across a fault
face: the bubble stiffness against quadrature, the condensed operator against the Schur complement of the full
system with the bubble dofs, a stuck face's mean jump (P1 + bubble) zero in the uncondensed solve and recovered
from the condensed one, and no bubble in a uniform stress state."""

import numpy as np

from pfault.faults import bubbles as bb
from pfault.faults import contact as ct
from pfault.mesh.serial import TET_FACES
from pfault.physics import elasticity as el

RNG = np.random.default_rng(3)
MINUS, PLUS = [0, 2, 1, 3], [0, 1, 2, 4]


def duffy_rule(n=5):
    """Points (barycentric, (q, 4)) and weights (sum 1/6) of a collapsed Gauss rule on the unit tetrahedron."""
    x, w = np.polynomial.legendre.leggauss(n)
    x, w = 0.5 * (x + 1), 0.5 * w
    u, v, s = np.meshgrid(x, x, x, indexing="ij")
    wu, wv, ws = np.meshgrid(w, w, w, indexing="ij")
    X, Y, Z = u, v * (1 - u), s * (1 - u) * (1 - v)
    W = wu * wv * ws * (1 - u) ** 2 * (1 - v)
    lam = np.stack([1 - X - Y - Z, X, Y, Z], axis=-1).reshape(-1, 4)
    return lam, W.ravel()


def patch():
    """Two tetrahedra sharing the face (0, 1, 2): minus cell (0, 2, 1, 3) below, plus cell (0, 1, 2, 4) above
    (both positively oriented); the face is local face 3 of both."""
    x = np.array([[0.0, 0.0, 0.0], [1.1, 0.1, 0.05], [0.2, 0.9, -0.1], [0.3, 0.3, -0.8], [0.35, 0.25, 0.9]])
    x += RNG.normal(scale=0.02, size=x.shape)
    minus, plus = x[MINUS], x[PLUS]
    an = el.triangle_area_normal(x[None, [0, 1, 2]])[0]
    if an[2] < 0:
        raise AssertionError("patch orientation")
    grad, vol = el.tet_geometry(np.stack([minus, plus]))
    if vol.min() <= 0:
        raise AssertionError("patch orientation")
    return x, grad, vol, an


def test_bubble_stiffness_against_quadrature():
    x, grad, vol, _ = patch()
    lam, mu = np.array([2.0e9, 2.0e9]), np.array([1.5e9, 1.5e9])
    lface = np.array([[3, 0], [3, 1]])      # two bubbles in each cell
    kub, kbb = bb.cell_blocks(grad, vol, lam, mu, lface)
    pts, w = duffy_rule()
    for c in range(2):
        # gradients of 27 l_i l_j l_k at the points, for each slot
        gphi = []
        for k in lface[c]:
            f = TET_FACES[k]
            gp = np.zeros((len(pts), 3))
            for p in f:
                others = [v for v in f if v != p]
                gp += 27 * (pts[:, others[0]] * pts[:, others[1]])[:, None] * grad[c, p][None]
            gphi.append(gp)
        G = np.stack(gphi, axis=1)                      # (q, m, 3)
        Gbb = 6 * vol[c] * np.einsum("q,qsi,qtj->stij", w, G, G)
        Gub = 6 * vol[c] * np.einsum("q,ai,qsj->asij", w, grad[c], G)
        Kbb = bb._elastic(Gbb[None], lam[:1], mu[:1])[0]
        Kub = bb._elastic(Gub[None], lam[:1], mu[:1])[0]
        assert np.allclose(kbb[c], Kbb, rtol=1e-12, atol=1e-6 * np.abs(Kbb).max())
        assert np.allclose(kub[c], Kub, rtol=1e-12, atol=1e-6 * np.abs(Kub).max())
        # the face mean: int grad(phi) dV = (9/20) A n_out
        assert np.allclose(6 * vol[c] * np.einsum("q,qsi->si", w, G), bb.bubble_gradient_mean(
            grad[c:c + 1], vol[c:c + 1], lface[c:c + 1])[0], atol=1e-12)


def full_and_condensed():
    """The two-cell patch with the fault face's multiplier: the full matrix over (u minus 12, u plus 12, b minus 3,
    b plus 3, t 3), its load, and the condensed data."""
    x, grad, vol, an = patch()
    A = np.linalg.norm(an)
    n = an / A
    R = ct.local_frames(n[None])[0]
    lam, mu = np.array([3.0e9, 1.0e9]), np.array([2.0e9, 0.7e9])
    K = el.stiffness(grad, vol, lam, mu)
    lface = np.array([[3], [3]])
    sign = np.array([[-1.0], [1.0]])
    cond = bb.condense(grad, vol, lam, mu, lface, sign, np.full((2, 1), A), np.broadcast_to(R, (2, 1, 3, 3)))
    Z = np.zeros((33, 33))
    Z[:12, :12], Z[12:24, 12:24] = K[0], K[1]
    for c in range(2):
        u, b = slice(12 * c, 12 * c + 12), slice(24 + 3 * c, 27 + 3 * c)
        Z[u, b], Z[b, u], Z[b, b] = cond.kub[c], cond.kub[c].T, np.linalg.inv(cond.kbb_inv[c])
    # A g_loc = sum sign (A/3) R u_face + sum sign (9/20) A R b
    Cu = np.zeros((3, 24))
    for c, s in ((0, -1.0), (1, 1.0)):
        for a in range(3):
            Cu[:, 12 * c + 3 * a:12 * c + 3 * a + 3] = s * A / 3 * R
    Cb = np.concatenate([cond.c[0, 0], cond.c[1, 0]], axis=1)
    Z[30:, :24], Z[:24, 30:] = Cu, Cu.T
    Z[30:, 24:30], Z[24:30, 30:] = Cb, Cb.T
    fb = np.concatenate([bb.pore_pressure_bubble_load(grad, vol, np.array([-3e5, 1e5]), lface),
                         bb.body_bubble_load(vol, np.array([[0, 0, -2e4], [0, 0, -2.5e4]]), lface)], axis=1)
    fb = fb[:, :3] + fb[:, 3:]
    return Z, Cu, fb, cond, K


def test_condensed_operator_is_schur_complement():
    Z, Cu, fb, cond, K = full_and_condensed()
    keep = np.r_[0:24, 30:33]
    b = np.r_[24:30]
    schur = Z[np.ix_(keep, keep)] - Z[np.ix_(keep, b)] @ np.linalg.solve(Z[np.ix_(b, b)], Z[np.ix_(b, keep)])
    Kc = np.zeros((24, 24))
    Kc[:12, :12], Kc[12:, 12:] = K[0] + cond.stiffness()[0], K[1] + cond.stiffness()[1]
    N, M = cond.displacement_of(), cond.traction_of()
    Bc = Cu.copy()
    Bc[:, :12] += N[0, 0]
    Bc[:, 12:] += N[1, 0]
    C = M[0, 0, 0] + M[1, 0, 0]
    scale = np.abs(schur).max()
    assert np.abs(schur[:24, :24] - Kc).max() < 1e-12 * scale
    assert np.abs(schur[24:, :24] - Bc).max() < 1e-12 * np.abs(Bc).max()
    assert np.abs(schur[:24, 24:] - Bc.T).max() < 1e-12 * np.abs(Bc).max()
    assert np.abs(schur[24:, 24:] - C).max() < 1e-12 * np.abs(C).max()
    # the multiplier block is symmetric negative definite: -C_s K_bb^-1 C_s^T summed over the sides
    assert np.linalg.eigvalsh(0.5 * (C + C.T)).max() < 0
    # the condensed load: -K_ub K_bb^-1 f_b on the displacements, C K_bb^-1 f_b on the face
    fu, gb = cond.load_of(fb)
    full_rhs = -Z[np.ix_(keep, b)] @ np.linalg.solve(Z[np.ix_(b, b)], fb.ravel())
    assert np.allclose(full_rhs[:24], fu.ravel(), rtol=0, atol=1e-12 * np.abs(fu).max())
    assert np.allclose(-full_rhs[24:], gb[:, 0].sum(axis=0), rtol=0, atol=1e-12 * np.abs(gb).max())


def test_stuck_face_mean_jump_zero_and_recovered():
    """Loaded patch with a stuck face (mean jump held at zero by the multiplier), the minus cell, the plus apex and
    one plus face vertex fixed: the full solve's mean jump (P1 + bubble) is zero, the condensed solve gives the same
    displacements and traction, and the bubbles recovered from it are the full solve's."""
    Z, Cu, fb, cond, K = full_and_condensed()
    f = np.zeros(33)
    f[12:24] = RNG.normal(size=12) * 1e6
    f[24:30] = fb.ravel()
    fixed = np.r_[0:15, 21:24]
    free = np.setdiff1d(np.arange(33), fixed)
    sol = np.zeros(33)
    sol[free] = np.linalg.solve(Z[np.ix_(free, free)], f[free])
    jump_full = Cu @ sol[:24] + np.concatenate([cond.c[0, 0], cond.c[1, 0]], axis=1) @ sol[24:30]
    assert np.abs(jump_full).max() < 1e-12 * np.abs(Cu @ sol[:24]).max()
    assert np.abs(Cu @ sol[:24]).max() > 1e-3 * np.abs(sol[:24]).max() * Cu.max()   # the P1 part alone is not
    # condensed: unknowns (u 24, t 3)
    Kc = np.zeros((24, 24))
    Kc[:12, :12], Kc[12:, 12:] = K[0] + cond.stiffness()[0], K[1] + cond.stiffness()[1]
    N, M = cond.displacement_of(), cond.traction_of()
    fu, gb = cond.load_of(fb)
    Bc = Cu + np.concatenate([N[0, 0], N[1, 0]], axis=1)
    Zc = np.block([[Kc, Bc.T], [Bc, M[0, 0, 0] + M[1, 0, 0]]])
    fc = np.concatenate([f[:24] + fu.ravel(), -gb[:, 0].sum(axis=0)])
    keep = np.setdiff1d(np.arange(27), fixed)
    solc = np.zeros(27)
    solc[keep] = np.linalg.solve(Zc[np.ix_(keep, keep)], fc[keep])
    assert np.allclose(solc[:24], sol[:24], rtol=0, atol=1e-10 * np.abs(sol[:24]).max())
    assert np.allclose(solc[24:], sol[30:], rtol=1e-10)
    b = cond.bubbles(solc[:24].reshape(2, 12), np.broadcast_to(solc[24:], (2, 1, 3)), fb)
    assert np.allclose(b.ravel(), sol[24:30], rtol=0, atol=1e-10 * np.abs(sol[24:30]).max())
    g = Cu @ solc[:24] + np.einsum("nsij,nsj->i", cond.c, b.reshape(2, 1, 3))
    assert np.abs(g).max() < 1e-10 * np.abs(Cu @ solc[:24]).max()


def test_uniform_stress_leaves_no_bubble():
    """A linear displacement field continuous across the face, with the face's traction R sigma n: the bubble
    rows are in equilibrium, so the bubbles vanish (the pair passes the patch test)."""
    x, grad, vol, an = patch()
    A = np.linalg.norm(an)
    n = an / A
    R = ct.local_frames(n[None])[0]
    lam, mu = np.array([3.0e9, 1.0e9]), np.array([2.0e9, 0.7e9])
    H = RNG.normal(size=(3, 3)) * 1e-4          # du/dx, the same in both cells
    E = 0.5 * (H + H.T)
    sig = [lam[c] * np.trace(E) * np.eye(3) + 2 * mu[c] * E for c in range(2)]
    if not np.allclose(sig[0] @ n, sig[1] @ n, atol=0):
        # traction continuity needs the same material: use the minus cell's on both sides
        lam, mu = np.full(2, lam[0]), np.full(2, mu[0])
        sig = [lam[0] * np.trace(E) * np.eye(3) + 2 * mu[0] * E] * 2
    lface = np.array([[3], [3]])
    cond = bb.condense(grad, vol, lam, mu, lface, np.array([[-1.0], [1.0]]), np.full((2, 1), A),
                       np.broadcast_to(R, (2, 1, 3, 3)))
    ue = np.stack([(x[MINUS] @ H.T).ravel(), (x[PLUS] @ H.T).ravel()])
    t = R @ sig[0] @ n
    b = cond.bubbles(ue, np.broadcast_to(t, (2, 1, 3)), np.zeros((2, 3)))
    assert np.abs(b).max() < 1e-12 * np.abs(ue).max()


def test_mean_strain_against_quadrature():
    """The bubbles' strain averaged over a cell (what the cells beside a fault add to their stress) against the
    quadrature of sym(grad(sum_s phi_s b_s)), two bubbles per cell."""
    x, grad, vol, _ = patch()
    lface = np.array([[3, 0], [3, 1]])
    b = RNG.normal(size=(2, 6)) * 1e-3
    eps = bb.mean_strain(grad, vol, lface, b)
    pts, w = duffy_rule()
    for c in range(2):
        h = np.zeros((3, 3))
        for s, k in enumerate(lface[c]):
            f = TET_FACES[k]
            gp = np.zeros((len(pts), 3))
            for p in f:
                others = [v for v in f if v != p]
                gp += 27 * (pts[:, others[0]] * pts[:, others[1]])[:, None] * grad[c, p][None]
            h += np.outer(b[c, 3 * s:3 * s + 3], 6 * np.einsum("q,qj->j", w, gp))
        assert np.allclose(eps[c], 0.5 * (h + h.T), rtol=0, atol=1e-12 * np.abs(h).max())
    # an empty slot adds nothing
    assert np.allclose(bb.mean_strain(grad, vol, np.array([[3, -1], [3, -1]]), b),
                       bb.mean_strain(grad, vol, np.array([[3], [3]]), b[:, :3]), rtol=0, atol=1e-15)
