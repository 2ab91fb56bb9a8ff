"""Contact/friction kernels: derivatives against finite differences in every state; active-set rules."""

import numpy as np
import pytest

from pfault.physics import contact as ct

RNG = np.random.default_rng(7)


def fd_check(fun, x, analytic, h=1e-7):
    num = np.zeros_like(analytic)
    for k in range(x.shape[1]):
        xp, xm = x.copy(), x.copy()
        xp[:, k] += h
        xm[:, k] -= h
        num[:, :, k] = (fun(xp) - fun(xm)) / (2 * h)
    scale = max(1.0, np.abs(analytic).max())
    return np.abs(num - analytic).max() / scale


def sample(n=40):
    area = RNG.uniform(0.5, 2.0, n)
    g = RNG.normal(size=(n, 3)) * 1e-2
    gp = RNG.normal(size=(n, 3)) * 1e-2
    t = RNG.normal(size=(n, 3)) * 1e5
    t[:, 0] = -np.abs(t[:, 0]) - 1e4
    coh = RNG.uniform(0, 1e4, n)
    tanphi = np.full(n, np.tan(np.radians(30)))
    return area, g, gp, t, coh, tanphi


@pytest.mark.parametrize("state", [ct.STICK, ct.SLIP, ct.OPEN])
@pytest.mark.parametrize("moving", [True, False])
def test_lagrange_rows_derivatives(state, moving):
    area, g, gp, t, coh, tanphi = sample()
    st = np.full(len(area), state)
    tol = np.full(len(area), 1e-12 if moving else 1.0)  # 'not moving': the slip increment is below tolerance
    r, dg, dt = ct.lagrange_rows(st, area, g, gp, t, coh, tanphi, tol)
    assert fd_check(lambda x: ct.lagrange_rows(st, area, x, gp, t, coh, tanphi, tol)[0], g, dg) < 1e-6
    assert fd_check(lambda x: ct.lagrange_rows(st, area, g, gp, x, coh, tanphi, tol)[0], t, dt, h=1e-2) < 1e-6


@pytest.mark.parametrize("state", [ct.STICK, ct.SLIP, ct.OPEN])
@pytest.mark.parametrize("reg", [0.0, 1e-3])
def test_augmented_slip_rows_derivatives(state, reg):
    area, g, gp, t, coh, tanphi = sample()
    st = np.full(len(area), state)
    c = np.full(len(area), 1e7)                      # E/h-like stiffness: c dg ~ t
    tol = np.full(len(area), 1e-12)
    eps = np.full(len(area), reg)
    r, dg, dt = ct.lagrange_rows(st, area, g, gp, t, coh, tanphi, tol, eps, c)
    assert fd_check(lambda x: ct.lagrange_rows(st, area, x, gp, t, coh, tanphi, tol, eps, c)[0], g, dg) < 1e-6
    assert fd_check(lambda x: ct.lagrange_rows(st, area, g, gp, x, coh, tanphi, tol, eps, c)[0], t, dt,
                    h=1e-2) < 1e-6


def test_augmented_slip_row_vanishes_on_the_cone_and_sticks_when_slip_reverses():
    """On the cone with the increment along the traction the augmented row is zero (maximum dissipation);
    an increment against the traction sends the face back to stick."""
    area, g, gp, t, coh, tanphi = sample(10)
    tau = ct.coulomb_limit(t[:, 0], coh, tanphi)
    d = g[:, 1:] - gp[:, 1:]
    t[:, 1:] = tau[:, None] * d / np.linalg.norm(d, axis=1)[:, None]
    g[:, 0] = 0.0
    c = np.full(10, 1e7)
    st = np.full(10, ct.SLIP)
    r, _, _ = ct.lagrange_rows(st, area, g, gp, t, coh, tanphi, np.full(10, 1e-12), None, c)
    assert np.abs(r).max() < 1e-9 * np.abs(t).max()
    new = ct.update_states(st, t, g, coh, tanphi, 1.0, 1e-9, 1e-3, dg_t=d, c_aug=c)
    assert np.all(new == ct.SLIP)
    new = ct.update_states(st, t, g, coh, tanphi, 1.0, 1e-9, 1e-3, dg_t=-d, c_aug=c)
    assert np.all(new == ct.STICK)


def test_slip_row_vanishes_on_the_coulomb_cone():
    area, g, gp, t, coh, tanphi = sample(10)
    tau = ct.coulomb_limit(t[:, 0], coh, tanphi)
    d = g[:, 1:] - gp[:, 1:]
    t[:, 1:] = tau[:, None] * d / np.linalg.norm(d, axis=1)[:, None]
    g[:, 0] = 0.0
    r, _, _ = ct.lagrange_rows(np.full(10, ct.SLIP), area, g, gp, t, coh, tanphi, np.full(10, 1e-12))
    assert np.abs(r).max() < 1e-9 * np.abs(t).max()


def test_penalty_derivatives_in_each_state():
    n = 60
    g = RNG.normal(size=(n, 3)) * 1e-3
    gp = RNG.normal(size=(n, 3)) * 1e-3
    tp = RNG.normal(size=(n, 3)) * 1e4
    kn = np.full(n, 1e9)
    kt = np.full(n, 1e9)
    coh = np.full(n, 1e3)
    tanphi = np.full(n, 0.5)
    t, d, state = ct.penalty_traction(g, gp, tp, kn, kt, coh, tanphi)
    assert set(np.unique(state)) == {ct.STICK, ct.SLIP, ct.OPEN}
    err = fd_check(lambda x: ct.penalty_traction(x, gp, tp, kn, kt, coh, tanphi)[0], g, d, h=1e-10)
    assert err < 1e-4


def test_active_set_rules():
    st = np.array([ct.STICK, ct.STICK, ct.STICK, ct.SLIP, ct.OPEN, ct.OPEN])
    t = np.array([[-1e5, 1e4, 0], [-1e5, 1e5, 0], [1e3, 0, 0], [-1e5, 1e3, 0], [0, 0, 0], [0, 0, 0]], float)
    g = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [1e-3, 0, 0], [-1e-3, 0, 0]], float)
    new = ct.update_states(st, t, g, np.zeros(6), np.full(6, np.tan(np.radians(30))), 1.0, 1e-9, 1e-3)
    assert list(new) == [ct.STICK, ct.SLIP, ct.OPEN, ct.STICK, ct.OPEN, ct.STICK]


def test_frames_are_orthonormal_and_right_handed():
    n = RNG.normal(size=(50, 3))
    R = ct.local_frames(n)
    assert np.allclose(np.einsum("nij,nkj->nik", R, R), np.eye(3))
    assert np.allclose(np.linalg.det(R), 1.0)
    v = ct.local_frames(np.array([[1.0, 0, 0]]))[0]
    assert np.allclose(v, [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
