"""Contact and Mohr-Coulomb friction per fault face, vectorised over faces (pure NumPy).

Conventions
- n: unit normal of a fault face pointing from the minus side to the plus side; R (3x3) has rows
  (n, m1, m2): local frame normal, strike-like and dip-like tangents.
- jump g = u_plus - u_minus (face average of the P1 jump); local g_loc = R g; g_N > 0 is opening.
- traction t (local): the traction the plus side exerts on the minus side; t_N < 0 is compression. The
  laws act on the effective traction (t_N + alpha p for a wet fault).
- Mohr-Coulomb with a tension cut-off: |t_T| <= tau_L = c - t_N tan(phi) and t_N <= T. By default (``apex``) the
  cut-off is the tensile strength T = c / tan(phi) where the cone's shear strength reaches zero (T = 0 without
  cohesion; a face with cohesion and phi = 0 never opens): a face opens when its normal traction reaches T, an
  open face carries T normal to it and no shear, and the strength surface has no jump where a face opens. A
  fault whose cut-off is at zero (-pfault_fault_<name>_tension_cutoff zero; ``FaceLaw.apex`` False) carries no
  tension: it opens at t_N = 0, where a cohesive face's shear strength drops from c to 0.

Lagrange faces: one semismooth complementarity residual per face (Alart-Curnier, the projection form of
Hueber, Stadler & Wohlmuth), with the augmented normal traction lam = t_N + c_N g_N and the augmented
tangential traction q = t_T + c_T dg_T (dg_T = g_T - g_T^n, the slip of the step):

    r_N = A (t_N - min(T, lam))                  closed (lam <= T): -A c_N g_N;  open: A (t_N - T)
    r_T = A (t_T - P_tau(q)),  tau = max(0, c - tan(phi) lam)   on closed faces, 0 on open ones

P_tau projects onto the disc of radius tau: stick (|q| <= tau) r_T = -A c_T dg_T; slip r_T = A (t_T - tau q/|q|),
which at a solution is the maximum-dissipation law (dg_T parallel to t_T, |t_T| = tau). The state of each face
is read from the iterate inside every evaluation; r is continuous across stick/slip, and across closed/open with
the cut-off at the apex (tau = c - tan(phi) T = 0 at the switch, with or without cohesion). With the cut-off at
t_N = 0 and cohesion the shear strength drops from c to 0 where the face opens, and r jumps there: Newton may cycle
a face between stuck and open (config/faulted_aquifer.opts at size factor 2, before the face bubbles: 200 Newton
iterations and 8 sub-steps in its fifth year, not converged; its slab at h = 8 m converges in at most 3 Newton
iterations a step with the bubbles). The rows are forces (Pa m^2), like the displacement rows. The solution does
not depend on c_N, c_T > 0 (stiffnesses, Pa/m, set per face by the interface from E/h); they only decide which
branch Newton takes. On Lagrange faces g is the face-mean jump with the part of the face bubbles
(pfault.faults.bubbles), which decreases with the face's own traction (d g / d t = -C K_bb^-1 C^T / A, negative
definite): t + c g stays increasing in t.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

STICK, SLIP, OPEN = 0, 1, 2
STATE_NAMES = ("stick", "slip", "open")


@dataclass(frozen=True)
class FaceLaw:
    """Per-face parameters of a contact law (arrays of the same length)."""
    area: np.ndarray        # m^2
    cohesion: np.ndarray    # Pa
    tan_phi: np.ndarray
    c_n: np.ndarray         # normal stiffness (Pa/m): augmentation (Lagrange) or penalty
    c_t: np.ndarray         # tangential stiffness (Pa/m)
    apex: np.ndarray | None = None  # bool: the tension cut-off at the cone's apex (True) or at t_N = 0; None: apex

    def __post_init__(self) -> None:
        if self.apex is None:
            object.__setattr__(self, "apex", np.ones(len(self.area), dtype=bool))

    def __getitem__(self, idx: np.ndarray | slice) -> FaceLaw:
        return FaceLaw(*(getattr(self, f.name)[idx] for f in fields(self)))

    def __len__(self) -> int:
        return len(self.area)


def local_frames(normal: np.ndarray) -> np.ndarray:
    """Rotation matrices (nf,3,3) with rows n, m1, m2; m1 horizontal (strike) unless n is near vertical."""
    n = normal / np.linalg.norm(normal, axis=1)[:, None]
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    m1 = np.cross(ref, n)
    m1 /= np.linalg.norm(m1, axis=1)[:, None]
    m2 = np.cross(n, m1)
    return np.stack([n, m1, m2], axis=1)


def coulomb_limit(t_n: np.ndarray, cohesion: np.ndarray, tan_phi: np.ndarray) -> np.ndarray:
    return np.maximum(cohesion - tan_phi * t_n, 0.0)


def tensile_strength(cohesion: np.ndarray, tan_phi: np.ndarray) -> np.ndarray:
    """T = c / tan(phi) (Pa): the normal traction at the apex of the Mohr-Coulomb cone, where its shear
    strength reaches zero; 0 without cohesion, infinite with cohesion and phi = 0 (such a face never opens)."""
    c = np.asarray(cohesion, dtype=float)
    tp = np.broadcast_to(np.asarray(tan_phi, dtype=float), c.shape)
    out = np.zeros(c.shape)
    pos = c > 0
    np.divide(c, tp, out=out, where=pos & (tp > 0))
    out[pos & ~(tp > 0)] = np.inf
    return out


def tension_cutoff(law: FaceLaw) -> np.ndarray:
    """The tension cut-off T of each face's law (Pa): the cone's apex c / tan(phi) (``tensile_strength``), or 0
    where the law's cut-off is at zero (``law.apex`` False)."""
    return np.where(law.apex, tensile_strength(law.cohesion, law.tan_phi), 0.0)


def states(law: FaceLaw, g: np.ndarray, g_prev: np.ndarray, t: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """Stick/slip/open of each face at the iterate (g, t): the branch of the semismooth residual. With tol > 0
    (Pa) a face within tol of a switch is reported in the branch that holds it in place (closed, stuck): at zero
    traction and zero jump a face is at once open, slipping and stuck, and round-off must not pick one."""
    lam = t[:, 0] + law.c_n * g[:, 0]
    strength = tension_cutoff(law)
    closed = lam <= strength + tol     # a face without traction and jump (a fresh fault) starts closed
    tau = np.where(closed, coulomb_limit(np.minimum(lam, strength), law.cohesion, law.tan_phi), 0.0)
    q = t[:, 1:] + law.c_t[:, None] * (g[:, 1:] - g_prev[:, 1:])
    slip = closed & (np.linalg.norm(q, axis=1) > tau + tol)
    return np.where(closed, np.where(slip, SLIP, STICK), OPEN)


def lagrange_rows(law: FaceLaw, g: np.ndarray, g_prev: np.ndarray, t: np.ndarray, state: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Semismooth residual rows r (nf,3) of the faces, their state, and the generalised derivatives
    d r/d g (nf,3,3) and d r/d t (nf,3,3) (local frame; t the effective traction). ``state``: the branches to
    take instead of the iterate's (stick or open only: the linear elastic trial of a step)."""
    nf = len(law)
    A, cn, ct_ = law.area, law.c_n, law.c_t
    st = states(law, g, g_prev, t) if state is None else np.asarray(state)
    r = np.zeros((nf, 3))
    dg = np.zeros((nf, 3, 3))
    dt = np.zeros((nf, 3, 3))
    opn = st == OPEN
    closed = ~opn
    # normal: closed -A c_N g_N, open A (t_N - T); no shear on an open face
    r[closed, 0] = -cn[closed] * g[closed, 0]
    dg[closed, 0, 0] = -cn[closed]
    r[opn] = t[opn]
    r[opn, 0] -= tension_cutoff(law[opn])
    dt[opn] = np.eye(3)[None]
    # stick: -A c_T dg_T
    stick = st == STICK
    r[stick, 1:] = -ct_[stick, None] * (g[stick, 1:] - g_prev[stick, 1:])
    dg[stick, 1, 1] = dg[stick, 2, 2] = -ct_[stick]
    i = np.nonzero(st == SLIP)[0]
    if len(i):
        lam = t[i, 0] + cn[i] * g[i, 0]
        raw = law.cohesion[i] - law.tan_phi[i] * lam
        tau = np.maximum(raw, 0.0)
        dtau = np.where(raw > 0, -law.tan_phi[i], 0.0)            # d tau / d lam
        q = t[i, 1:] + ct_[i, None] * (g[i, 1:] - g_prev[i, 1:])
        qn = np.linalg.norm(q, axis=1)                              # > tau >= 0 on a slipping face
        s = q / qn[:, None]
        proj = (np.eye(2)[None] - np.einsum("ni,nj->nij", s, s)) / qn[:, None, None]    # d s / d q
        r[i, 1:] = t[i, 1:] - tau[:, None] * s
        dt[i, 1:, 1:] = np.eye(2)[None] - tau[:, None, None] * proj
        dg[i, 1:, 1:] = -(tau * ct_[i])[:, None, None] * proj
        dt[i, 1:, 0] = -dtau[:, None] * s
        dg[i, 1:, 0] = -(dtau * cn[i])[:, None] * s
    return st, r * A[:, None], dg * A[:, None, None], dt * A[:, None, None]


def penalty_jump(law: FaceLaw, g: np.ndarray, t: np.ndarray, t0_n: np.ndarray) -> np.ndarray:
    """The jump a penalty face's Lagrange rows act on: its jump less the penalty's compliance,
    g - (t_N - t0_N, t_T) / (k_N, k_T) (``law``: the penalty stiffnesses; t the effective traction and t0_n the
    initial effective normal traction). The rows ``lagrange_rows`` on it (a perturbed Lagrangian) hold
    t_N = t0_N + k_N g_N while closed and t_T = t_T^n + k_T dg_T while stuck, and slip along the return map's trial
    t_T^n + k_T dg_T: the penalty law; d(jump)/dt = -1/k."""
    te = np.array(t, dtype=float, copy=True)
    te[:, 0] -= t0_n
    return g - te / np.stack([law.c_n, law.c_t, law.c_t], axis=1)
