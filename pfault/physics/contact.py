"""Fault contact and Mohr-Coulomb friction on interface faces, vectorised over faces (pure NumPy).

Conventions
- n: unit normal of a fault face pointing from the minus side to the plus side; R (3x3) has rows
  (n, m1, m2): local frame normal, strike-like and dip-like tangents.
- jump g = u_plus - u_minus (face average of the P1 jump); local g_loc = R g; g_N > 0 is opening.
- traction t (local, the multiplier): the traction the plus side exerts on the minus side; t_N < 0 is
  compression. The minus side receives +t, the plus side -t.
- Mohr-Coulomb: |t_T| <= tau_L = c - t_N tan(phi).

Lagrange multiplier rows (per face, area A), as in the stick/slip/open active-set method:
- stick: r = A [g_N, g_T - g_T^n]           (closed, no incremental slip)
- slip:  r = A [g_N, t_T - tau_L s]         s = q/|q|, q = t_T + c dg_T, dg_T = g_T - g_T^n, c = E/h
         (augmented direction; the kernel also offers s = dg_T/|dg_T|)
- open:  r = A t                              (traction-free)
"""

from __future__ import annotations

import numpy as np

STICK, SLIP, OPEN = 0, 1, 2
STATE_NAMES = ("stick", "slip", "open")


def local_frames(normal):
    """Rotation matrices (nf,3,3) with rows n, m1, m2; m1 horizontal (strike) unless n is near vertical."""
    n = normal / np.linalg.norm(normal, axis=1)[:, None]
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    m1 = np.cross(ref, n)
    m1 /= np.linalg.norm(m1, axis=1)[:, None]
    m2 = np.cross(n, m1)
    return np.stack([n, m1, m2], axis=1)


def coulomb_limit(t_n, cohesion, tan_phi):
    return np.maximum(cohesion - tan_phi * t_n, 0.0)


def lagrange_rows(state, area, g_loc, g_prev_loc, t, cohesion, tan_phi, slide_tol, slip_reg=None, c_aug=None):
    """Residual rows (nf,3) and their derivatives d r/d g_loc (nf,3,3), d r/d t (nf,3,3).

    Slip direction: with c_aug (nf,) > 0 (a stiffness, Pa/m) the augmented direction
    s = q/|q|, q = t_T + c dg_T (Alart-Curnier, Hueber-Wohlmuth): at a solution t_T = tau_L s and dg_T is
    parallel to s, so it is the maximum-dissipation law, and it stays smooth while a face starts to slip
    (|q| >= |t_T|); without c_aug, s = dg_T/|dg_T| (the traction's direction before any increment).
    slip_reg (nf,) > 0 regularises the direction, s = q / sqrt(|q|^2 + (c eps)^2) (s = dg_T /
    sqrt(|dg_T|^2 + eps^2) without c_aug), at the price of a traction below the limit for slips much
    smaller than eps."""
    nf = len(area)
    r = np.zeros((nf, 3))
    dg = np.zeros((nf, 3, 3))
    dt = np.zeros((nf, 3, 3))
    A = area
    closed = state != OPEN
    # normal row of closed faces: A g_N
    r[closed, 0] = A[closed] * g_loc[closed, 0]
    dg[closed, 0, 0] = A[closed]
    stick = state == STICK
    r[stick, 1:] = A[stick, None] * (g_loc[stick, 1:] - g_prev_loc[stick, 1:])
    dg[stick, 1, 1] = dg[stick, 2, 2] = A[stick]
    i = np.nonzero(state == SLIP)[0]
    if len(i):
        # slip rows: A [t_T - tau_L s]; the two laws differ in the direction s
        tau = coulomb_limit(t[i, 0], cohesion[i], tan_phi[i])
        dtau_dtn = np.where(cohesion[i] - tan_phi[i] * t[i, 0] > 0, -tan_phi[i], 0.0)
        if c_aug is not None:
            _slip_rows_augmented(i, A, g_loc, g_prev_loc, t, tau, dtau_dtn, c_aug, slip_reg, r, dg, dt)
        else:
            _slip_rows_increment(i, A, g_loc, g_prev_loc, t, tau, dtau_dtn, slide_tol, slip_reg, r, dg, dt)
    opn = state == OPEN
    r[opn] = A[opn, None] * t[opn]
    dt[opn] = A[opn, None, None] * np.eye(3)[None]
    return r, dg, dt


def _slip_rows_increment(i, A, g_loc, g_prev_loc, t, tau, dtau_dtn, slide_tol, slip_reg, r, dg, dt):
    """Slip rows of faces i with s = dg_T/|dg_T| (the traction's direction before any increment)."""
    d = g_loc[i, 1:] - g_prev_loc[i, 1:]
    dn = np.linalg.norm(d, axis=1)
    moving = dn > slide_tol[i]
    # slip direction from the slip increment
    j = i[moving]
    if len(j):
        eps2 = np.zeros(len(j)) if slip_reg is None else slip_reg[j] ** 2
        dm = d[moving]
        nrm = np.sqrt(dn[moving] ** 2 + eps2)
        s = dm / nrm[:, None]
        tm = tau[moving]
        r[j, 1:] = A[j, None] * (t[j, 1:] - tm[:, None] * s)
        dt[j, 1, 1] = dt[j, 2, 2] = A[j]
        dt[j, 1:, 0] = -A[j, None] * dtau_dtn[moving, None] * s
        ds = (np.eye(2)[None] - np.einsum("ni,nj->nij", s, s)) / nrm[:, None, None]
        dg[j, 1:, 1:] = -(A[j] * tm)[:, None, None] * ds
    # no increment yet: slip along the traction
    j = i[~moving]
    if len(j):
        tt = t[j, 1:]
        tn = np.linalg.norm(tt, axis=1)
        tm = tau[~moving]
        safe = tn > 1e-300
        inv = np.where(safe, 1.0 / np.where(safe, tn, 1.0), 0.0)
        ratio = tm * inv
        r[j, 1:] = A[j, None] * tt * (1.0 - ratio)[:, None]
        eye = np.eye(2)[None]
        unit_t = tt * inv[:, None]
        outer = np.einsum("ni,nj->nij", unit_t, unit_t) * inv[:, None, None]
        dtt = (1.0 - ratio)[:, None, None] * eye + np.where(safe, tm, 0.0)[:, None, None] * outer
        dt[j, 1:, 1:] = A[j, None, None] * dtt
        unit = np.where(safe[:, None], tt / np.where(safe, tn, 1.0)[:, None], 0.0)
        dt[j, 1:, 0] = -A[j, None] * dtau_dtn[~moving, None] * unit


def _slip_rows_augmented(i, A, g_loc, g_prev_loc, t, tau, dtau_dtn, c, slip_reg, r, dg, dt):
    """Slip rows of faces i with the augmented direction s = q/|q|, q = t_T + c dg_T."""
    ci = c[i]
    q = t[i, 1:] + ci[:, None] * (g_loc[i, 1:] - g_prev_loc[i, 1:])
    eps2 = np.zeros(len(i)) if slip_reg is None else (ci * slip_reg[i]) ** 2
    nrm = np.sqrt(np.einsum("ni,ni->n", q, q) + eps2)
    safe = nrm > 1e-300
    inv = np.where(safe, 1.0 / np.where(safe, nrm, 1.0), 0.0)
    s = q * inv[:, None]
    ds = (np.eye(2)[None] - np.einsum("ni,nj->nij", s, s)) * inv[:, None, None]      # d s / d q
    Ai = A[i]
    r[i, 1:] = Ai[:, None] * (t[i, 1:] - tau[:, None] * s)
    dt[i, 1:, 1:] = Ai[:, None, None] * (np.eye(2)[None] - tau[:, None, None] * ds)
    dt[i, 1:, 0] = -Ai[:, None] * dtau_dtn[:, None] * s
    dg[i, 1:, 1:] = -(Ai * tau * ci)[:, None, None] * ds


def update_states(state, t, g_loc, cohesion, tan_phi, traction_tol, opening_tol, slip_tol_ratio,
                  slip_to_stick=True, dg_t=None, c_aug=None):
    """Next active set from the converged solution of the current one (with hysteresis).

    open -> stick when the faces interpenetrate (g_N < -opening_tol);
    closed -> open when the normal traction is tensile (t_N > traction_tol);
    stick -> slip when |t_T| > tau_L (1 + slip_tol_ratio); slip -> stick when |t_T| < tau_L (1 - slip_tol_ratio)
    (not with a regularised slip law, where a slipping face whose increment is blocked already behaves as
    stuck; faces return to stick at the start of the next step).
    """
    new = state.copy()
    opn = state == OPEN
    new[opn & (g_loc[:, 0] < -opening_tol)] = STICK
    closed = ~opn
    tension = closed & (t[:, 0] > traction_tol)
    new[tension] = OPEN
    rest = closed & ~tension
    tau = coulomb_limit(t[:, 0], cohesion, tan_phi)
    tt = np.linalg.norm(t[:, 1:], axis=1)
    new[rest & (state == STICK) & (tt > tau * (1 + slip_tol_ratio) + traction_tol * 1e-3)] = SLIP
    if c_aug is not None and dg_t is not None:
        # augmented slip law: |t_T| = tau_L on a slipping face; it sticks again when its slip increment
        # turns against its traction (|t_T + c dg_T| < tau_L)
        along = np.einsum("ni,ni->n", dg_t, t[:, 1:]) / np.maximum(tt, 1e-300)
        new[rest & (state == SLIP) & (c_aug * along < -slip_tol_ratio * tau)] = STICK
    elif slip_to_stick:
        new[rest & (state == SLIP) & (tt < tau * (1 - slip_tol_ratio))] = STICK
    return new


def violation(state, new, t, g_loc, cohesion, tan_phi, traction_tol, opening_tol):
    """How strongly each face asks for its change of state (larger first); 0 where nothing changes."""
    tau = coulomb_limit(t[:, 0], cohesion, tan_phi)
    tt = np.linalg.norm(t[:, 1:], axis=1)
    ref = np.maximum(tau, traction_tol)
    v = np.zeros(len(state))
    v = np.where((state != OPEN) & (new == OPEN), t[:, 0] / ref, v)
    v = np.where((state == STICK) & (new == SLIP), (tt - tau) / ref, v)
    v = np.where((state == SLIP) & (new == STICK), (tau - tt) / ref, v)
    v = np.where((state == OPEN) & (new == STICK), -g_loc[:, 0] / np.maximum(opening_tol, 1e-300), v)
    return np.where(new != state, np.maximum(v, 1e-300), 0.0)


def penalty_traction(g_loc, g_prev_loc, t_prev, kn, kt, cohesion, tan_phi, t0_n=None):
    """Penalty contact: traction (nf,3), derivative dt/dg_loc (nf,3,3) and state.

    t_N = t0_N + kn g_N while in contact (t_N <= 0), 0 when open; tangential return map from t_T^n + kt dg_T.
    t0_N is the initial normal traction (prestress), 0 by default.
    """
    nf = len(g_loc)
    t = np.zeros((nf, 3))
    d = np.zeros((nf, 3, 3))
    state = np.full(nf, OPEN)
    t0n = np.zeros(nf) if t0_n is None else t0_n
    tn_trial = t0n + kn * g_loc[:, 0]
    closed = tn_trial <= 0
    t[closed, 0] = tn_trial[closed]
    d[closed, 0, 0] = kn[closed]
    trial = t_prev[:, 1:] + kt[:, None] * (g_loc[:, 1:] - g_prev_loc[:, 1:])
    tau = coulomb_limit(t[:, 0], cohesion, tan_phi)
    dtau_dtn = np.where(cohesion - tan_phi * t[:, 0] > 0, -tan_phi, 0.0)
    tn = np.linalg.norm(trial, axis=1)
    stick = closed & (tn <= tau)
    slip = closed & ~stick
    t[stick, 1:] = trial[stick]
    d[stick, 1, 1] = d[stick, 2, 2] = kt[stick]
    state[stick] = STICK
    if np.any(slip):
        s = trial[slip] / tn[slip, None]
        t[slip, 1:] = tau[slip, None] * s
        proj = np.eye(2)[None] - np.einsum("ni,nj->nij", s, s)
        d[slip, 1:, 1:] = (tau[slip] * kt[slip] / tn[slip])[:, None, None] * proj
        d[slip, 1:, 0] = (dtau_dtn[slip] * kn[slip])[:, None] * s
        state[slip] = SLIP
    return t, d, state


def transition_counts(old, new):
    """3x3 table: counts[i, j] faces going from state i to state j."""
    c = np.zeros((3, 3), dtype=np.int64)
    np.add.at(c, (old, new), 1)
    return c
