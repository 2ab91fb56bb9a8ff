"""Transient groundwater flow on P1 tetrahedra: element kernels, specific storage, Theis solution.

Equation for the hydraulic head change h (m, 0 initially, negative is a drawdown):

    S_s dh/dt - div(K grad h) = -Q delta(wells)

with K the (isotropic) hydraulic conductivity (m/s), S_s the specific storage (1/m) and Q the pumping
rate (m**3/s, positive is extraction). The pore-pressure change that loads the skeleton is dp = rho_w g h.

Pure NumPy: no PETSc here.
"""

from __future__ import annotations

import numpy as np

from .elasticity import oedometric_compressibility, tet_geometry  # noqa: F401  (tet_geometry re-exported)

WATER_COMPRESSIBILITY = 4.4e-10   # 1/Pa, beta_w of water at about 20 C
EULER_GAMMA = 0.57721566490153286061


# -- element matrices --------------------------------------------------------------------------
def conductivity(grad: np.ndarray, vol: np.ndarray, k: float | np.ndarray) -> np.ndarray:
    """Element conductivity matrices (n,4,4): A_ab = V K g_a . g_b (gradients from tet_geometry)."""
    k = np.broadcast_to(np.asarray(k, float), vol.shape)
    return (vol * k)[:, None, None] * np.einsum("nai,nbi->nab", grad, grad)


_CONSISTENT = (np.ones((4, 4)) + np.eye(4)) / 20.0
_LUMPED = np.eye(4) / 4.0


def mass(vol: np.ndarray, storage: float | np.ndarray = 1.0, lumped: bool = False) -> np.ndarray:
    """Element storage (mass) matrices (n,4,4): consistent M_ab = S_s V (1 + delta_ab) / 20,
    or lumped M_ab = S_s V delta_ab / 4."""
    s = np.broadcast_to(np.asarray(storage, float), vol.shape)
    return (vol * s)[:, None, None] * (_LUMPED if lumped else _CONSISTENT)


# -- storage -------------------------------------------------------------------------------------
def porosity(void_ratio: float | np.ndarray) -> np.ndarray:
    """n = e / (1 + e)."""
    e = np.asarray(void_ratio, float)
    return e / (1.0 + e)


def specific_storage(young: float | np.ndarray, poisson: float | np.ndarray, void_ratio: float | np.ndarray,
                     biot: float | np.ndarray = 1.0, water_density: float = 1000.0, gravity: float = 9.80665,
                     water_compressibility: float = WATER_COMPRESSIBILITY) -> np.ndarray:
    """Specific storage (1/m) of a confined layer under oedometric (laterally confined) deformation:

        S_s = rho_w g (alpha c_M + n beta_w)

    c_M = (1+nu)(1-2nu) / (E (1-nu)) is the oedometric compressibility of the drained skeleton (1/Pa),
    alpha the Biot coefficient, n = e/(1+e) the porosity from the void ratio e and beta_w the water
    compressibility (4.4e-10 1/Pa). Grain compressibility is neglected. (A fully consistent Biot storage
    would have alpha**2 c_M; the two coincide for alpha = 1, the default.)
    """
    c_m = oedometric_compressibility(np.asarray(young, float), np.asarray(poisson, float))
    return water_density * gravity * (np.asarray(biot, float) * c_m + porosity(void_ratio) * water_compressibility)


# -- wells ---------------------------------------------------------------------------------------
def vertical_line_in_tets(grad: np.ndarray, vol: np.ndarray, x0: np.ndarray, xw: float, yw: float, z_bottom: float,
                          z_top: float, side: tuple[int, int] = (1, 1),
                          tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Intersection of the vertical segment x = xw, y = yw, z_bottom <= z <= z_top with tetrahedra.

    grad, vol: from tet_geometry; x0: (n,3) coordinates of each tet's vertex 0.
    Returns (length (n,), mid (n,4)): the length of the part of the segment inside each tet and the
    barycentric coordinates of that part's midpoint, so that int phi_a ds = length * mid[:, a].

    A segment that runs along a vertical face or edge shared by several tetrahedra is given to exactly
    one of them: ties are broken as if the axis were moved to (xw + sx eps, yw + sy eps**2), (sx, sy) =
    side, for an infinitesimal eps (symbolic perturbation), which depends on the geometry only, not on
    numbering or partition. Non-vertical faces cut the axis at a point and need no rule. On the outer
    boundary the perturbation must point into the mesh (choose ``side``; the caller checks coverage).
    """
    sx, sy = side
    n = len(vol)
    g = grad                                        # (n,4,3): lambda_a(x) = lam0_a + g_a . (x - x0)
    lam0 = np.empty((n, 4))
    lam0[:, 0] = 1.0
    lam0[:, 1:] = 0.0
    d = np.array([xw, yw, 0.0]) - x0                # (n,3): lambda at (xw, yw, z = 0)
    c = lam0 + np.einsum("nai,ni->na", g, d)        # lambda_a(z) = c_a + gz_a z
    gz = g[:, :, 2]
    scale = np.linalg.norm(g, axis=2)               # |g_a| ~ 1/h
    vertical = np.abs(gz) <= tol * scale            # faces parallel to the axis
    # on a vertical face the sign of lambda is constant along the axis; ties by the perturbation
    tie = np.abs(c) <= tol
    gx, gy = sx * g[:, :, 0], sy * g[:, :, 1]
    pert_pos = (gx > tol * scale) | ((np.abs(gx) <= tol * scale) & (gy > 0))
    vertical_ok = np.where(tie, pert_pos, c > 0)
    inside = np.all(~vertical | vertical_ok, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        zcut = np.where(vertical, 0.0, -c / np.where(vertical, 1.0, gz))
    lo = np.where(~vertical & (gz > 0), zcut, -np.inf).max(axis=1)
    hi = np.where(~vertical & (gz < 0), zcut, np.inf).min(axis=1)
    lo = np.maximum(lo, z_bottom)
    hi = np.minimum(hi, z_top)
    length = np.where(inside, np.maximum(hi - lo, 0.0), 0.0)
    zmid = np.where(length > 0, 0.5 * (lo + hi), 0.0)
    mid = c + gz * zmid[:, None]
    mid = np.where(length[:, None] > 0, mid, 0.0)
    return length, mid


# -- exponential integral and Theis --------------------------------------------------------------
def exp_integral_e1(u: float | np.ndarray) -> np.ndarray:
    """Exponential integral E1(u) = int_u^inf exp(-s)/s ds for u > 0 (the Theis well function W(u)).

    Power series E1 = -gamma - ln u - sum_k (-u)^k / (k k!) for u < 1; for u >= 1 the continued
    fraction exp(-u) / (u + 1 - 1/(u + 3 - 4/(u + 5 - ...))) evaluated by the modified Lentz method.
    Relative accuracy ~1e-15 on [1e-12, 50].
    """
    u = np.asarray(u, float)
    out = np.full(u.shape, np.nan)
    out[u == 0] = np.inf
    small = (u > 0) & (u < 1)
    if np.any(small):
        x = u[small]
        total = np.zeros_like(x)
        term = np.ones_like(x)                     # (-x)^k / k!
        for k in range(1, 40):
            term = term * (-x) / k
            total += term / k
        out[small] = -EULER_GAMMA - np.log(x) - total
    large = u >= 1
    if np.any(large):
        x = u[large]
        tiny = 1e-300
        b = x + 1.0
        c = np.full_like(x, 1.0 / tiny)
        d = 1.0 / b
        h = d.copy()
        for i in range(1, 500):
            a = -float(i * i)
            b = b + 2.0
            d = 1.0 / (a * d + b)
            c = b + a / c
            delta = c * d
            h *= delta
            if np.all(np.abs(delta - 1.0) < 1e-16):
                break
        out[large] = h * np.exp(-x)
    return out


def theis_drawdown(r: float | np.ndarray, t: float | np.ndarray, Q: float, T: float, S: float) -> np.ndarray:
    """Theis drawdown s = Q / (4 pi T) W(u), u = r**2 S / (4 T t) (m, positive down) at distance r (m) and
    time t (s) after a well in an infinite confined aquifer started pumping Q (m**3/s); T = K b (m**2/s)
    is the transmissivity and S = S_s b the storativity."""
    r = np.asarray(r, float)
    u = r ** 2 * S / (4.0 * T * np.asarray(t, float))
    return Q / (4.0 * np.pi * T) * exp_integral_e1(u)
