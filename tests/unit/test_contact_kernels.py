"""Contact/friction kernels (pfault.faults.contact): the semismooth residual's generalised derivative against
finite differences in every state away from the kinks, its zeros (the contact conditions), its continuity
across the stick/slip and closed/open switches with and without cohesion (the tension cut-off at the cone's
apex), and its independence of the augmentation; the penalty law as the solver runs it (the Lagrange rows on the
penalty's compliant jump, ``penalty_jump``) against the penalty return map written out here.
"""

import numpy as np
import pytest

from pfault.faults import contact as ct

RNG = np.random.default_rng(7)
TAN30 = np.tan(np.radians(30))


def fd_check(fun, x, analytic, h=1e-7):
    num = np.zeros_like(analytic)
    for k in range(x.shape[1]):
        xp, xm = x.copy(), x.copy()
        xp[:, k] += h
        xm[:, k] -= h
        num[:, :, k] = (fun(xp) - fun(xm)) / (2 * h)
    scale = max(1.0, np.abs(analytic).max())
    return np.abs(num - analytic).max() / scale


def penalty_traction(law, g, g_prev, t_prev, t0_n):
    """The penalty law, written out as a return map (the reference): t_N = t0_N + k_N g_N while t_N <= T (the
    tension cut-off: the apex c / tan(phi), or 0), T when open; the shear's trial t_T^n + k_T (g_T - g_T^n) returned
    onto the Mohr-Coulomb cone (no shear when open). Returns the traction and the state."""
    kn, kt = law.c_n, law.c_t
    strength = ct.tension_cutoff(law)
    tn = t0_n + kn * g[:, 0]
    closed = tn <= strength
    t = np.zeros_like(g)
    t[:, 0] = np.where(closed, tn, strength)
    trial = t_prev[:, 1:] + kt[:, None] * (g[:, 1:] - g_prev[:, 1:])
    tau = ct.coulomb_limit(t[:, 0], law.cohesion, law.tan_phi)
    size = np.linalg.norm(trial, axis=1)
    stick = closed & (size <= tau)
    slip = closed & ~stick
    t[stick, 1:] = trial[stick]
    t[slip, 1:] = tau[slip, None] * trial[slip] / size[slip, None]
    return t, np.where(stick, ct.STICK, np.where(slip, ct.SLIP, ct.OPEN))


def law(n, cohesion=True, c=1e7):
    coh = RNG.uniform(0, 1e4, n) if cohesion else np.zeros(n)
    return ct.FaceLaw(RNG.uniform(0.5, 2.0, n), coh, np.full(n, TAN30), np.full(n, c), np.full(n, 0.7 * c))


def sample(state, n=60):
    """Iterates (g, g_prev, t) whose faces all lie in ``state``, at least 5 % away from every kink."""
    lw = law(4 * n)
    g = RNG.normal(size=(4 * n, 3)) * 1e-2
    gp = RNG.normal(size=(4 * n, 3)) * 1e-2
    t = RNG.normal(size=(4 * n, 3)) * 1e5
    if state != ct.OPEN:
        g[:, 0] = RNG.normal(size=4 * n) * 1e-4
        t[:, 0] = -np.abs(t[:, 0]) - 5e4
    lam = t[:, 0] + lw.c_n * g[:, 0]
    strength = ct.tensile_strength(lw.cohesion, lw.tan_phi)
    tau = ct.coulomb_limit(np.minimum(lam, strength), lw.cohesion, lw.tan_phi)
    q = np.linalg.norm(t[:, 1:] + lw.c_t[:, None] * (g[:, 1:] - gp[:, 1:]), axis=1)
    away = (np.abs(lam - strength) > 0.05 * np.abs(t[:, 0]) + 1.0) & (np.abs(q - tau) > 0.05 * tau + 1.0)
    keep = np.nonzero((ct.states(lw, g, gp, t) == state) & away)[0][:n]
    assert len(keep) >= 10, "sampler found too few faces in the state"
    return lw[keep], g[keep], gp[keep], t[keep]


@pytest.mark.parametrize("state", [ct.STICK, ct.SLIP, ct.OPEN])
def test_semismooth_derivatives_in_each_state(state):
    lw, g, gp, t = sample(state)
    st, r, dg, dt = ct.lagrange_rows(lw, g, gp, t)
    assert np.all(st == state)
    assert fd_check(lambda x: ct.lagrange_rows(lw, x, gp, t)[1], g, dg, h=1e-9) < 1e-6
    assert fd_check(lambda x: ct.lagrange_rows(lw, g, gp, x)[1], t, dt, h=1e-2) < 1e-6


def test_zeros_are_the_contact_conditions():
    """r = 0 exactly on: a closed stuck face (no normal jump, no slip increment, |t_T| <= tau); a slipping face
    whose traction is on the Coulomb limit along its slip increment; an open face whose traction is the tensile
    strength c / tan(phi) normal to it."""
    n = 12
    lw = law(n, c=5e6)
    gp = RNG.normal(size=(n, 3)) * 1e-2
    t = np.zeros((n, 3))
    g = gp.copy()
    t[:, 0] = -RNG.uniform(1e5, 1e6, n)
    tau = ct.coulomb_limit(t[:, 0], lw.cohesion, lw.tan_phi)
    stick, slip, opn = np.arange(n) % 3 == 0, np.arange(n) % 3 == 1, np.arange(n) % 3 == 2
    # stick: any traction inside the cone
    d = RNG.normal(size=(n, 2))
    d /= np.linalg.norm(d, axis=1)[:, None]
    t[stick, 1:] = 0.6 * tau[stick, None] * d[stick]
    # slip: increment along the traction, traction on the cone
    g[slip, 1:] = gp[slip, 1:] + 1e-3 * d[slip]
    t[slip, 1:] = tau[slip, None] * d[slip]
    g[:, 0] = 0.0
    # open: opening, the tensile strength normal to the face, no shear
    g[opn, 0] = 1e-3
    t[opn] = 0.0
    t[opn, 0] = lw.cohesion[opn] / lw.tan_phi[opn]
    assert np.all(t[opn, 0] > 0)
    st, r, _, _ = ct.lagrange_rows(lw, g, gp, t)
    assert list(st) == [ct.STICK, ct.SLIP, ct.OPEN] * (n // 3)
    assert np.abs(r).max() < 1e-9 * np.abs(t).max()
    # and not a zero when the conditions are violated: shear above the cone on a face that does not slip
    t2 = t.copy()
    t2[stick, 1:] = 1.5 * tau[stick, None] * d[stick]
    _, r2, _, _ = ct.lagrange_rows(lw, g, gp, t2)
    assert np.all(np.linalg.norm(r2[stick], axis=1) > 0.1 * tau[stick] * lw.area[stick])


def test_the_solution_does_not_depend_on_the_augmentation():
    """Where r = 0 for one c it is zero for any c > 0 (the same contact conditions), and the state is the same."""
    n = 9
    lw = law(n, c=1e6)
    gp = np.zeros((n, 3))
    g = np.zeros((n, 3))
    t = np.zeros((n, 3))
    t[:, 0] = -1e5
    tau = ct.coulomb_limit(t[:, 0], lw.cohesion, lw.tan_phi)
    g[3:6, 1] = 2e-3
    t[3:6, 1] = tau[3:6]
    g[6:, 0], t[6:] = 1e-3, 0.0
    t[6:, 0] = ct.tensile_strength(lw.cohesion[6:], lw.tan_phi[6:])
    t[:3, 1] = 0.5 * tau[:3]
    for c in (1e3, 1e6, 1e9, 1e12):
        lc = ct.FaceLaw(lw.area, lw.cohesion, lw.tan_phi, np.full(n, c), np.full(n, c))
        st, r, _, _ = ct.lagrange_rows(lc, g, gp, t)
        assert list(st) == [ct.STICK] * 3 + [ct.SLIP] * 3 + [ct.OPEN] * 3
        assert np.abs(r).max() < 1e-9 * 1e5


def test_residual_is_continuous_across_the_switches():
    """Without cohesion r is continuous where a face changes state: stick/slip at |q| = tau and closed/open at
    lam = 0 (a semismooth function, so Newton's steps see no jumps)."""
    lw = ct.FaceLaw(np.full(2, 1.5), np.zeros(2), np.full(2, TAN30), np.full(2, 1e6), np.full(2, 0.7e6))
    gp = np.zeros((2, 3))
    # stick/slip: shear traction crossing the limit
    t = np.array([[-1e5, 0, 0], [-1e5, 0, 0]], float)
    tau = TAN30 * 1e5
    g = np.zeros((2, 3))
    t[0, 1], t[1, 1] = tau * (1 - 1e-9), tau * (1 + 1e-9)
    st, r, _, _ = ct.lagrange_rows(lw, g, gp, t)
    assert list(st) == [ct.STICK, ct.SLIP]
    assert abs(r[0, 1] - r[1, 1]) < 1e-6 * tau
    # closed/open: augmented normal traction crossing zero
    t = np.array([[-1e-6, 50.0, 0], [1e-6, 50.0, 0]])
    st, r, _, _ = ct.lagrange_rows(lw, g, gp, t)
    assert st[0] != ct.OPEN and st[1] == ct.OPEN
    assert np.abs(r[0] - r[1]).max() < 1e-3


@pytest.mark.parametrize("phi", [30.0, 10.0])
def test_residual_with_cohesion_is_continuous_where_a_face_opens(phi):
    """With cohesion c the face opens where its augmented normal traction reaches the cone's apex
    T = c / tan(phi), where the shear strength is zero: r (all three rows, a slipping or stuck face against an
    open one) has no jump there. A cut-off at t_N = 0 would drop the shear row by A c."""
    c, tphi, area = 1e5, np.tan(np.radians(phi)), 1.5
    strength = c / tphi
    lw = ct.FaceLaw(np.full(4, area), np.full(4, c), np.full(4, tphi), np.full(4, 1e6), np.full(4, 0.7e6))
    gp = np.zeros((4, 3))
    g = np.zeros((4, 3))
    g[:, 1] = 1e-4                              # a slip increment: slipping once the strength is below |q|
    eps = 1e-9 * strength
    t = np.array([[strength - eps, 50.0, 0], [strength + eps, 50.0, 0],
                  [-1e3, 0.0, 0], [0.0, 0.0, 0]], float)
    st, r, _, _ = ct.lagrange_rows(lw, g, gp, t)
    assert st[0] == ct.SLIP and st[1] == ct.OPEN
    assert np.abs(r[0] - r[1]).max() < 1e-6 * area * strength
    # below the apex the face is closed and holds shear up to c - tan(phi) t_N: under zero normal traction c
    assert st[2] == ct.STICK or st[2] == ct.SLIP
    assert np.isclose(ct.coulomb_limit(t[3, 0], c, tphi), c)
    assert ct.states(lw[np.array([3])], np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)))[0] == ct.STICK
    # the penalty law: the same cut-off, continuous traction
    gn = np.array([(strength - eps) / 1e6, (strength + eps) / 1e6])
    gpen = np.zeros((2, 3))
    gpen[:, 0] = gn
    gpen[:, 1] = 1e-4
    tp, stp = penalty_traction(lw[np.arange(2)], gpen, np.zeros((2, 3)), np.zeros((2, 3)), np.zeros(2))
    assert list(stp) == [ct.SLIP, ct.OPEN]
    assert np.abs(tp[0] - tp[1]).max() < 1e-6 * strength


def test_tensile_strength():
    """T = c / tan(phi); 0 without cohesion (whatever phi), infinite with cohesion and phi = 0."""
    s = ct.tensile_strength(np.array([1e5, 0.0, 0.0, 1e5]), np.array([TAN30, TAN30, 0.0, 0.0]))
    assert np.isclose(s[0], 1e5 / TAN30) and s[1] == 0 and s[2] == 0 and np.isinf(s[3])


def test_a_cutoff_at_zero_opens_at_zero_normal_traction():
    """FaceLaw.apex False (-pfault_fault_<name>_tension_cutoff zero): a cohesive face (c = 100 kPa, apex 173 kPa)
    is closed 1 Pa below t_N = 0 and open 1 Pa above it, where the apex law (FaceLaw's default) keeps it closed and
    stuck; its open rows are A t (no tension, no shear); the Lagrange and penalty laws agree; the derivatives of the
    open rows against finite differences."""
    n = 4
    coh = np.full(n, 1e5)
    apex = ct.FaceLaw(np.full(n, 2.0), coh, np.full(n, TAN30), np.full(n, 1e6), np.full(n, 0.7e6))
    zero = ct.FaceLaw(apex.area, coh, apex.tan_phi, apex.c_n, apex.c_t, np.zeros(n, dtype=bool))
    assert np.all(apex.apex) and np.array_equal(ct.tension_cutoff(apex), ct.tensile_strength(coh, apex.tan_phi))
    assert np.all(ct.tension_cutoff(zero) == 0.0)
    z = np.zeros((n, 3))
    t = np.zeros((n, 3))
    t[:, 0] = [-1.0, 1.0, -1.0, 1.0]
    t[:, 1] = 0.5e5                                      # half the cohesion: inside the cone
    assert list(ct.states(zero, z, z, t)) == [ct.STICK, ct.OPEN] * 2
    assert list(ct.states(apex, z, z, t)) == [ct.STICK] * 4
    st, r, dg, dt = ct.lagrange_rows(zero, z, z, t)
    opn = st == ct.OPEN
    assert np.array_equal(r[opn], (zero.area[:, None] * t)[opn])
    assert fd_check(lambda x: ct.lagrange_rows(zero, z, z, x, state=st)[1], t, dt, h=1e-2) < 1e-6
    g = np.zeros((n, 3))
    g[:, 0] = [-1e-6, 1e-6, -1e-6, 1e-6]                 # the penalty trial t_N = c_N g_N: -1 and +1 Pa
    _, pst = penalty_traction(zero, g, z, np.zeros((n, 3)), np.zeros(n))
    assert list(pst) == [ct.STICK, ct.OPEN] * 2


def test_fresh_fault_starts_closed():
    """No traction, no jump: the face is closed and stuck (a glued fault), not open."""
    lw = law(3)
    z = np.zeros((3, 3))
    assert list(ct.states(lw, z, z, z)) == [ct.STICK] * 3


@pytest.mark.parametrize("c", [1e5, 1e7, 1e9])
def test_penalty_faces_rows_vanish_at_the_penalty_law(c):
    """What the solver runs on a penalty face: the Lagrange rows on its compliant jump (``penalty_jump``). At the
    traction of the penalty return map (stuck, slipping and open faces, with and without cohesion, an initial normal
    traction) the rows are zero and the face is in the law's state, whatever the augmentation c of the rows."""
    n = 300
    k = RNG.uniform(1e8, 1e10, n)
    apex = np.arange(n) % 3 != 0                        # every third face's cut-off at zero
    pen = ct.FaceLaw(RNG.uniform(0.5, 2.0, n), np.where(np.arange(n) % 2 == 0, 0.0, RNG.uniform(0, 1e5, n)),
                     np.full(n, TAN30), k, RNG.uniform(0.5, 1.0, n) * k, apex)
    rows = ct.FaceLaw(pen.area, pen.cohesion, pen.tan_phi, np.full(n, c), np.full(n, 0.7 * c), apex)
    g = RNG.normal(size=(n, 3)) * 1e-4
    g_prev = RNG.normal(size=(n, 3)) * 1e-4
    t0_n = -RNG.uniform(0.0, 2e5, n)
    t_prev = np.column_stack([t0_n, RNG.normal(size=(n, 2)) * 2e4])
    t, state = penalty_traction(pen, g, g_prev, t_prev, t0_n)
    assert set(np.unique(state)) == {ct.STICK, ct.SLIP, ct.OPEN}
    g_law = ct.penalty_jump(pen, g, t, t0_n)
    g_prev_law = ct.penalty_jump(pen, g_prev, t_prev, t0_n)
    st, r, _, _ = ct.lagrange_rows(rows, g_law, g_prev_law, t)
    assert np.array_equal(st, state)
    assert np.abs(r).max() < 1e-9 * np.abs(t).max() * pen.area.max()


def test_penalty_jump_derivative():
    """d(penalty_jump)/dt = -1/k per component: what the fault term adds to a penalty face's dr/dt."""
    n = 20
    pen = law(n)
    g, t, t0 = RNG.normal(size=(n, 3)), RNG.normal(size=(n, 3)) * 1e5, RNG.normal(size=n) * 1e5
    d = np.zeros((n, 3, 3))
    d[:, 0, 0], d[:, 1, 1], d[:, 2, 2] = -1.0 / pen.c_n, -1.0 / pen.c_t, -1.0 / pen.c_t
    assert fd_check(lambda x: ct.penalty_jump(pen, g, x, t0), t, d, h=1.0) < 1e-12


def test_frames_are_orthonormal_and_right_handed():
    n = RNG.normal(size=(50, 3))
    R = ct.local_frames(n)
    assert np.allclose(np.einsum("nij,nkj->nik", R, R), np.eye(3))
    assert np.allclose(np.linalg.det(R), 1.0)
    v = ct.local_frames(np.array([[1.0, 0, 0]]))[0]
    assert np.allclose(v, [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
