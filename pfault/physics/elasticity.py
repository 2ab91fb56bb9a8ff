"""Small-strain isotropic linear elasticity on P1 tetrahedra, vectorised over cells.

Conventions: tension positive; total stress sigma = C:eps(u) + sigma0 - alpha * dp * I, with dp the
pore-pressure change (negative for a drawdown). Voigt order xx, yy, zz, yz, xz, xy with engineering shear.
"""

from __future__ import annotations

import numpy as np


def lame(young: float | np.ndarray, poisson: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    young = np.asarray(young, float)
    poisson = np.asarray(poisson, float)
    lam = young * poisson / ((1 + poisson) * (1 - 2 * poisson))
    mu = young / (2 * (1 + poisson))
    return lam, mu


def oedometric_compressibility(young: float | np.ndarray, poisson: float | np.ndarray) -> float | np.ndarray:
    """c_M = (1+nu)(1-2nu) / (E (1-nu)): vertical strain per unit vertical effective stress."""
    return (1 + poisson) * (1 - 2 * poisson) / (young * (1 - poisson))


def tet_geometry(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shape-function gradients (n,4,3) and volumes (n,) of tetrahedra with vertex coordinates x (n,4,3)."""
    jac = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=1)  # rows are edges
    det = np.linalg.det(jac)
    inv = np.linalg.inv(jac)  # columns give d(xi)/dx
    g = np.empty((len(x), 4, 3))
    g[:, 1:, :] = np.transpose(inv, (0, 2, 1))
    g[:, 0, :] = -g[:, 1:, :].sum(axis=1)
    return g, det / 6.0


def stiffness(grad: np.ndarray, vol: np.ndarray, lam: float | np.ndarray, mu: float | np.ndarray) -> np.ndarray:
    """Element stiffness matrices (n,12,12), dof order (vertex, component).

    K[a i, b j] = V (lam g_ai g_bj + mu g_aj g_bi + mu delta_ij g_a . g_b)

    Built from batched outer products (matmul), fastest on batches of a few thousand cells that stay in cache.
    """
    n = len(vol)
    a = grad * (vol * np.broadcast_to(lam, (n,)))[:, None, None]
    b = grad * (vol * np.broadcast_to(mu, (n,)))[:, None, None]
    row = grad.reshape(n, 1, 12)
    k = np.matmul(a.reshape(n, 12, 1), row).reshape(n, 4, 3, 4, 3)
    k += np.matmul(b.reshape(n, 12, 1), row).reshape(n, 4, 3, 4, 3).transpose(0, 1, 4, 3, 2)
    dot = np.matmul(b, grad.transpose(0, 2, 1))
    for i in range(3):
        k[:, :, i, :, i] += dot
    return k.reshape(n, 12, 12)


def strain(grad: np.ndarray, ue: np.ndarray) -> np.ndarray:
    """Cell strain tensors (n,3,3) from element displacements ue (n,4,3)."""
    h = np.einsum("nai,naj->nij", ue, grad)  # du_i/dx_j
    return 0.5 * (h + np.transpose(h, (0, 2, 1)))


def stress(eps: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """sigma = lam tr(eps) I + 2 mu eps, per cell."""
    tr = np.trace(eps, axis1=1, axis2=2)
    return lam[:, None, None] * tr[:, None, None] * np.eye(3) + 2 * mu[:, None, None] * eps


def stress_divergence_force(grad: np.ndarray, vol: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Nodal internal forces (n,4,3): f_a = V sigma . g_a, for a constant cell stress (n,3,3)."""
    return vol[:, None, None] * np.einsum("nij,naj->nai", sigma, grad)


def pore_pressure_force(grad: np.ndarray, vol: np.ndarray, alpha_dp: np.ndarray) -> np.ndarray:
    """Nodal forces (n,4,3) of the Biot load: f_a = V alpha dp g_a (moved to the right-hand side).

    From div(C:eps - alpha dp I) = 0: K u = f_ext + int B^T alpha dp m.
    """
    return vol[:, None, None] * alpha_dp[:, None, None] * grad


def body_force(vol: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Nodal forces (n,4,3) of a constant body force per cell b (n,3) with P1 weights V/4."""
    return np.repeat((vol[:, None] * b / 4.0)[:, None, :], 4, axis=1)


def triangle_area_normal(x: np.ndarray) -> np.ndarray:
    """Area-weighted normals (n,3) (|n| = area) of triangles x (n,3,3)."""
    return 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
