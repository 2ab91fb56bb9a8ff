"""Face bubbles of the fault faces and their static condensation (pure NumPy kernels).

Each cell adjacent to a fault face carries, for each of its fault faces, one vector-valued face bubble
phi = 27 l_i l_j l_k of the face's three vertices (3 dofs): it vanishes on the cell's other faces, so it lives
in that cell alone. The face-mean jump of a face, which its P0 traction acts on, is that of the P1 displacement
plus (9/20) (b_plus - b_minus). The bubbles are eliminated cell by cell: from the cell's bubble rows

    K_bu u + K_bb b - f_b + sum_s C_s^T (t_s - t0_s) = 0,       C_s = sign_s (9/20) A_s R_s (3 x 3, slot s)

b = K_bb^-1 (f_b - K_bu u - sum_s C_s^T dt_s). In the condensed system the displacement block is
K_uu - K_ub K_bb^-1 K_bu, the displacement rows take the load -K_ub K_bb^-1 f_b and the forces
-K_ub K_bb^-1 C_s^T dt_s, and the law of a face takes the mean jump with its bubble part
sum over its two cells of C_s b / A (an affine function of u and the tractions of the faces sharing a cell).

Conventions as pfault.physics.elasticity (dof order vertex, component) and pfault.faults.contact (local frames,
jump plus - minus, traction of the plus side on the minus side). Cell slots: local face k (opposite vertex k,
pfault.mesh.serial.TET_FACES) of each of the cell's fault faces, -1 for an empty slot.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from math import factorial

import numpy as np

from ..mesh.serial import TET_FACES
from ..physics import elasticity as el

MEAN = 9.0 / 20.0          # mean of 27 l_i l_j l_k over its face
VOLUME_MEAN = 9.0 / 40.0   # its mean over the cell


def _quartic_table() -> np.ndarray:
    """T[k1, k2, p, q] = (1 / V) int (prod of face k1's vertices but p) (prod of face k2's vertices but q) dV
    (exact: int l^a dV = 6 V a! / (|a| + 3)!); zero where p is not on face k1 or q not on face k2."""
    T = np.zeros((4, 4, 4, 4))
    for k1 in range(4):
        for k2 in range(4):
            for p in TET_FACES[k1]:
                for q in TET_FACES[k2]:
                    a = np.zeros(4, int)
                    for v in TET_FACES[k1]:
                        a[v] += v != p
                    for v in TET_FACES[k2]:
                        a[v] += v != q
                    T[k1, k2, p, q] = 6.0 * np.prod([factorial(x) for x in a]) / factorial(int(a.sum()) + 3)
    return T


QUARTIC = _quartic_table()


def bubble_gradient_mean(grad: np.ndarray, vol: np.ndarray, lface: np.ndarray) -> np.ndarray:
    """int grad(phi) dV (n, m, 3) of the bubbles of local faces ``lface`` (n, m): (9/20) A n_out = -(27/20) V
    grad(l_k) (zero for an empty slot)."""
    w = -(27.0 / 20.0) * vol[:, None, None] * np.take_along_axis(grad, np.maximum(lface, 0)[:, :, None], axis=1)
    return np.where(lface[:, :, None] >= 0, w, 0.0)


def _elastic(G: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """K[.., a i, b j] = lam G[a b i j] + mu G[a b j i] + mu delta_ij G[a b k k] from the moments
    G[n, a, b, i, j] = int d_i phi_a d_j phi_b dV; returns (n, 3 na, 3 nb)."""
    n, na, nb = G.shape[:3]
    k = lam[:, None, None, None, None] * G + mu[:, None, None, None, None] * np.swapaxes(G, 3, 4)
    k = k + (mu[:, None, None] * np.trace(G, axis1=3, axis2=4))[:, :, :, None, None] * np.eye(3)
    return k.transpose(0, 1, 3, 2, 4).reshape(n, 3 * na, 3 * nb)


def cell_blocks(grad: np.ndarray, vol: np.ndarray, lam: np.ndarray, mu: np.ndarray, lface: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Elastic blocks of cells with bubbles on local faces ``lface`` (n, m; -1 empty): K_ub (n, 12, 3m) and
    K_bb (n, 3m, 3m). An empty slot has K_bb = identity (scaled) and no coupling, so it stays zero."""
    n, m = lface.shape
    w = bubble_gradient_mean(grad, vol, lface)                              # (n, m, 3)
    Gub = np.einsum("nai,nsj->nasij", grad, w)                              # int d_i l_a d_j phi_s
    k = np.maximum(lface, 0)
    T = QUARTIC[k[:, :, None], k[:, None, :]]                               # (n, m, m, 4, 4)
    Gbb = 729.0 * vol[:, None, None, None, None] * np.einsum("nstpq,npi,nqj->nstij", T, grad, grad)
    empty = lface < 0
    Gbb = np.where(empty[:, :, None, None, None] | empty[:, None, :, None, None], 0.0, Gbb)
    Kub = _elastic(Gub, lam, mu)
    Kbb = _elastic(Gbb, lam, mu)
    if np.any(empty):
        scale = (mu * vol / np.maximum(vol, 1e-300) ** (2.0 / 3.0))[:, None]
        d = np.repeat(empty, 3, axis=1) * scale
        Kbb = Kbb + d[:, :, None] * np.eye(3 * m)[None]
    return Kub, Kbb


@dataclass(frozen=True)
class Condensed:
    """Per cell with bubbles (n cells, m slots): ``kub`` K_ub (n, 12, 3m), ``kbb_inv`` K_bb^-1 (n, 3m, 3m) and the
    traction coupling of each slot ``c`` (n, m, 3, 3): C_s = sign (9/20) A R of the slot's face (zero when empty),
    in jump-times-area units (m^3 per m of bubble dof)."""
    kub: np.ndarray
    kbb_inv: np.ndarray
    c: np.ndarray

    @property
    def slots(self) -> int:
        return self.c.shape[1]

    def ct(self) -> np.ndarray:
        """C^T as one (n, 3m, 3m) block-diagonal matrix: column block s is slot s's C_s^T."""
        n, m = self.c.shape[:2]
        out = np.zeros((n, m, 3, m, 3))
        idx = np.arange(m)
        out[:, idx, :, idx, :] = np.swapaxes(self.c, 2, 3).transpose(1, 0, 2, 3)
        return out.reshape(n, 3 * m, 3 * m)

    def stiffness(self) -> np.ndarray:
        """-K_ub K_bb^-1 K_bu (n, 12, 12): what condensation adds to the cells' P1 stiffness."""
        return -self.kub @ self.kbb_inv @ np.swapaxes(self.kub, 1, 2)

    def displacement_of(self) -> np.ndarray:
        """N[e, s] (n, m, 3, 12): d(A g_s)/d u_e of each slot's face through the bubbles, -C_s (K_bb^-1 K_bu)_s."""
        n, m = self.c.shape[:2]
        x = (self.kbb_inv @ np.swapaxes(self.kub, 1, 2)).reshape(n, m, 3, 12)
        return -np.einsum("nsij,nsjk->nsik", self.c, x)

    def traction_of(self) -> np.ndarray:
        """M[e, s, r] (n, m, m, 3, 3): d(A g_s)/d t_r of slot s's face through the bubbles,
        -C_s (K_bb^-1)_{s r} C_r^T."""
        n, m = self.c.shape[:2]
        kinv = self.kbb_inv.reshape(n, m, 3, m, 3).transpose(0, 1, 3, 2, 4)
        return -np.einsum("nsij,nsrjk,nrlk->nsril", self.c, kinv, self.c)

    def load_of(self, fb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For bubble loads fb (n, 3m): the condensed displacement load -K_ub K_bb^-1 fb (n, 12) and the bubble
        part of each slot's A g, C_s (K_bb^-1 fb)_s (n, m, 3)."""
        n, m = self.c.shape[:2]
        y = np.einsum("nij,nj->ni", self.kbb_inv, fb)
        return -np.einsum("nij,nj->ni", self.kub, y), np.einsum("nsij,nsj->nsi", self.c, y.reshape(n, m, 3))

    def bubbles(self, ue: np.ndarray, dt: np.ndarray, fb: np.ndarray) -> np.ndarray:
        """Bubble dofs b (n, 3m) of cells with P1 dofs ue (n, 12), slot tractions' changes dt (n, m, 3) and loads
        fb (n, 3m)."""
        ct_dt = np.einsum("nsji,nsj->nsi", self.c, dt).reshape(len(ue), 3 * self.slots)
        rhs = fb - np.einsum("nai,na->ni", self.kub, ue) - ct_dt
        return np.einsum("nij,nj->ni", self.kbb_inv, rhs)


def condense(grad: np.ndarray, vol: np.ndarray, lam: np.ndarray, mu: np.ndarray, lface: np.ndarray,
             sign: np.ndarray, area: np.ndarray, R: np.ndarray) -> Condensed:
    """Condensation data of cells with bubbles on local faces ``lface`` (n, m; -1 empty), each slot's face with
    side ``sign`` (-1 minus, +1 plus), area and local frame R (n, m) / (n, m, 3, 3)."""
    kub, kbb = cell_blocks(grad, vol, lam, mu, lface)
    c = np.where((lface >= 0)[:, :, None, None], (sign * MEAN * area)[:, :, None, None] * R, 0.0)
    return Condensed(kub, np.linalg.inv(kbb), c)


def pore_pressure_bubble_load(grad: np.ndarray, vol: np.ndarray, alpha_dp: np.ndarray, lface: np.ndarray
                              ) -> np.ndarray:
    """Biot load of the bubbles, alpha dp int div(phi e_i) = alpha dp (9/20) A n_out (n, 3m), as
    elasticity.pore_pressure_force for the P1 functions."""
    return (alpha_dp[:, None, None] * bubble_gradient_mean(grad, vol, lface)).reshape(len(vol), 3 * lface.shape[1])


def mean_strain(grad: np.ndarray, vol: np.ndarray, lface: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Strain of the bubbles b (n, 3m) of local faces ``lface`` (n, m) averaged over their cells (n, 3, 3):
    sym(sum_s b_s (x) int grad(phi_s) dV) / V."""
    w = bubble_gradient_mean(grad, vol, lface)                                         # (n, m, 3)
    b = b.reshape(len(vol), lface.shape[1], 3)
    h = np.einsum("nsi,nsj->nij", b, w) / vol[:, None, None]                        # d b_i / d x_j
    return 0.5 * (h + np.swapaxes(h, 1, 2))


def body_bubble_load(vol: np.ndarray, b: np.ndarray, lface: np.ndarray) -> np.ndarray:
    """Load of a constant body force b (n, 3) per cell on the bubbles: (9/40) V b each (n, 3m)."""
    f = (VOLUME_MEAN * vol[:, None] * b)[:, None, :] * (lface >= 0)[:, :, None]
    return f.reshape(len(vol), 3 * lface.shape[1])


@dataclass(frozen=True)
class BubbleLoad:
    """A load on the bubbles of a rank's enriched cells: ``fb`` (ne, 3m) and its part of each slot's A g,
    ``g_load`` (ne, m, 3) (``CellBubbles.load``)."""
    fb: np.ndarray
    g_load: np.ndarray


class CellBubbles:
    """The bubbles of the cells on both sides of a rank's fault faces, condensed: what they add to the
    cells' stiffness, to the faces' mean jumps, to the displacement rows and to the Jacobian, in the rank's local
    dof numbering (pure NumPy; the interface turns it into PETSc insertions).

    ``side_cell``, ``side_lface`` (nf, 2): the minus and plus cells of each owned face (local ids) and the face's
    local face in each; ``cell_dofs`` (nc, 12) local dofs; ``fixed`` a mask of the local dofs held by Dirichlet
    conditions (they take no force); ``cells`` (grad, vol, lam, mu) of all local cells (lam, mu: the bubbles'
    moduli); ``area``, ``R`` of the faces; ``to_global`` maps local dofs to global ones (taking integers of the
    type ``index_type``)."""

    def __init__(self, side_cell: np.ndarray, side_lface: np.ndarray, cell_dofs: np.ndarray,
                 fixed: np.ndarray, cells: tuple, area: np.ndarray, R: np.ndarray, to_global: Callable,
                 index_type: type = np.int64) -> None:
        grad, vol, lam, mu = cells
        face = np.repeat(np.arange(len(side_cell)), 2)
        side = np.tile([0, 1], len(face) // 2)
        cell, lface = side_cell[face, side], side_lface[face, side]
        self.cell, inv = np.unique(cell, return_inverse=True)            # enriched cells (local ids)
        order = np.lexsort((lface, inv))
        first = np.searchsorted(inv[order], inv[order])
        slot = np.empty(len(face), np.int64)
        slot[order] = np.arange(len(face)) - first
        ne, m = len(self.cell), int(slot.max()) + 1 if len(face) else 1
        self.face = np.full((ne, m), -1)                                   # owned face of each slot
        lf = np.full((ne, m), -1)
        sign = np.zeros((ne, m))
        self.face[inv, slot], lf[inv, slot], sign[inv, slot] = face, lface, np.where(side == 0, -1.0, 1.0)
        self.lface = lf
        f = np.maximum(self.face, 0)
        c = self.cell
        self.cond = condense(grad[c], vol[c], lam[c], mu[c], lf, sign, area[f], R[f])
        self.N = self.cond.displacement_of()            # (ne, m, 3, 12)
        self.M = self.cond.traction_of()                # (ne, m, m, 3, 3)
        self.dofs = cell_dofs[c]
        self.free = ~fixed[self.dofs]
        self.nf = len(area)
        self._grad, self._vol = grad[c], vol[c]
        self.lam, self.mu = lam[c], mu[c]               # the bubbles' moduli in the enriched cells
        self._to_global, self._int = to_global, index_type

    @property
    def valid(self) -> np.ndarray:
        return self.face >= 0

    def g_dofs(self, local: np.ndarray) -> np.ndarray:
        """Global numbers of local dofs (any shape)."""
        local = np.asarray(local)
        if local.size == 0:
            return local.astype(np.int64)
        return np.asarray(self._to_global(local.ravel().astype(self._int))).reshape(local.shape)

    def stiffness(self) -> tuple[np.ndarray, np.ndarray]:
        """(local dofs (ne, 12), -K_ub K_bb^-1 K_bu (ne, 12, 12)) to add to the cells' stiffness."""
        return self.dofs, self.cond.stiffness()

    # -- loads -----------------------------------------------------------------------------------
    def zero_load(self) -> BubbleLoad:
        """No load on the bubbles (the initial state's, which loads nothing)."""
        ne, m = self.face.shape
        return BubbleLoad(np.zeros((ne, 3 * m)), np.zeros((ne, m, 3)))

    def load(self, fb: np.ndarray, out: np.ndarray) -> BubbleLoad:
        """The bubbles' load fb (ne, 3m), with its part of the faces' jumps; adds its condensed displacement load
        -K_ub K_bb^-1 fb to the local array ``out`` (free dofs)."""
        fu, g_load = self.cond.load_of(fb)
        out += np.bincount(self.dofs.ravel(), weights=(fu * self.free).ravel(), minlength=len(out))
        return BubbleLoad(fb, g_load)

    def pore_pressure_load(self, alpha_dp: np.ndarray) -> np.ndarray:
        """Bubble load of the Biot term for alpha dp per local cell."""
        return pore_pressure_bubble_load(self._grad, self._vol, alpha_dp[self.cell], self.lface)

    def body_load(self, b: np.ndarray) -> np.ndarray:
        """Bubble load of body forces b (nc, 3) per local cell."""
        return body_bubble_load(self._vol, b[self.cell], self.lface)

    def jump_of_load(self, load: BubbleLoad) -> np.ndarray:
        """The load's part of each face's A g (nf, 3; local frame)."""
        out = np.zeros((self.nf, 3))
        np.add.at(out, self.face[self.valid], load.g_load[self.valid])
        return out

    # -- residual ----------------------------------------------------------------------------------
    def jump(self, u_loc: np.ndarray, dt: np.ndarray, load: BubbleLoad) -> np.ndarray:
        """The bubbles' part of A g (nf, 3; local frame, zero on faces without bubbles) at displacements u_loc and
        tractions' changes dt (nf, 3) since the initial state, under ``load``."""
        ue = u_loc[self.dofs]
        dts = dt[np.maximum(self.face, 0)] * self.valid[:, :, None]            # (ne, m, 3)
        ag = (np.einsum("nsik,nk->nsi", self.N, ue) + np.einsum("nsrij,nrj->nsi", self.M, dts) + load.g_load)
        out = np.zeros((self.nf, 3))
        v = self.valid
        np.add.at(out, self.face[v], ag[v])
        return out

    def forces(self, dt: np.ndarray, out: np.ndarray) -> None:
        """Add the displacement rows' forces of the tractions' changes through the bubbles,
        -K_ub K_bb^-1 C^T dt = sum_s N_s^T dt_s, to the local array ``out`` (free dofs)."""
        dts = dt[np.maximum(self.face, 0)] * self.valid[:, :, None]
        fu = np.einsum("nsik,nsi->nk", self.N, dts) * self.free
        out += np.bincount(self.dofs.ravel(), weights=fu.ravel(), minlength=len(out))

    def bubble_dofs(self, u_loc: np.ndarray, dt: np.ndarray, load: BubbleLoad) -> np.ndarray:
        """The bubble dofs b (ne, 3m) recovered from the condensed solution under ``load``."""
        dts = dt[np.maximum(self.face, 0)] * self.valid[:, :, None]
        return self.cond.bubbles(u_loc[self.dofs], dts, load.fb)

    def cell_strain(self, u_loc: np.ndarray, dt: np.ndarray, load: BubbleLoad) -> np.ndarray:
        """The bubbles' strain averaged over each enriched cell (ne, 3, 3), recovered from the condensed solution
        (``bubble_dofs``): sym(sum_s b_s (x) int grad(phi_s) dV) / V. The stress is linear in it, so the cell
        mean of the stress of P1 plus bubbles is C:(eps(u) + this)."""
        return mean_strain(self._grad, self._vol, self.lface, self.bubble_dofs(u_loc, dt, load))

    def cell_stress(self, u_loc: np.ndarray, dt: np.ndarray, load: BubbleLoad) -> np.ndarray:
        """The stress of the bubbles' mean strain (``cell_strain``) in their moduli (ne, 3, 3): what they add to each
        enriched cell's mean stress."""
        return el.stress(self.cell_strain(u_loc, dt, load), self.lam, self.mu)

    # -- Jacobian ----------------------------------------------------------------------------------
    def jacobian_blocks(self, drdg: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Blocks of the Jacobian through the bubbles, for the faces' law derivatives
        drdg = d r / d(A g) (nf, 3, 3): as (kind, rows, cols, values) with kind 'fu' (face rows, local dof
        columns (n, 12), values (n, 3, 12)), 'ff' (face rows, face columns, (n, 3, 3)) and 'uf' (local dof rows
        (n, 12), face columns, (n, 12, 3))."""
        e, s = np.nonzero(self.valid)
        f = self.face[e, s]
        fu = np.einsum("nij,njk->nik", drdg[f], self.N[e, s]) * self.free[e][:, None, :]
        uf = np.swapaxes(self.N[e, s], 1, 2) * self.free[e][:, :, None]
        e2, s2, r2 = np.nonzero(self.valid[:, :, None] & self.valid[:, None, :])
        ff = np.einsum("nij,njk->nik", drdg[self.face[e2, s2]], self.M[e2, s2, r2])
        return [("fu", f, self.dofs[e], fu), ("ff", self.face[e2, s2], self.face[e2, r2], ff),
                ("uf", self.dofs[e], f, uf)]

    def pattern(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """Index pairs of the blocks: (faces, dofs (n, 12)) of 'fu' and 'uf', (faces, faces) of 'ff'."""
        e, s = np.nonzero(self.valid)
        e2, s2, r2 = np.nonzero(self.valid[:, :, None] & self.valid[:, None, :])
        return (self.face[e, s], self.dofs[e]), (self.face[e2, s2], self.face[e2, r2])
