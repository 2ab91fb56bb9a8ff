"""The cells' forces and tangent stiffness blocks of the soil term, vectorised over cells (NumPy), and their
insertion into PETSc matrices through global indices (-1: a constrained dof, whose entries are left out: the
operator's rows and columns there are the identity's)."""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

ADD = PETSc.InsertMode.ADD_VALUES


def cell_forces(grad: np.ndarray, vol: np.ndarray, stress: np.ndarray) -> np.ndarray:
    """Nodal forces (n, 12) of a constant stress per cell (n,3,3): f_a = V sigma g_a."""
    return (vol[:, None, None] * np.einsum("nij,naj->nai", stress, grad)).reshape(len(vol), 12)


def shear_stiffness(grad: np.ndarray, vol: np.ndarray) -> np.ndarray:
    """The part of the element matrices (n,12,12) that a shear modulus mu multiplies, for mu = 1:
    V (g_ak g_bi + delta_ik g_a . g_b) (dof order (vertex, component)); constant per cell."""
    n = len(vol)
    b = grad * vol[:, None, None]
    k = np.matmul(b.reshape(n, 12, 1), grad.reshape(n, 1, 12)).reshape(n, 4, 3, 4, 3).transpose(0, 1, 4, 3, 2).copy()
    dot = np.matmul(b, grad.transpose(0, 2, 1))
    for i in range(3):
        k[:, :, i, :, i] += dot
    return k.reshape(n, 12, 12)


def tangent_stiffness(grad: np.ndarray, vol: np.ndarray, a: np.ndarray, mu: np.ndarray,
                      shear: np.ndarray | None = None) -> np.ndarray:
    """Element matrices (n,12,12), dof order (vertex, component), of the tangent D = a (x) I + 2 mu (I_sym - I (x) I/3)
    (pfault.physics.soil.update):
        K[a i, b k] = V ((A g_a)_i g_bk + mu g_ak g_bi + mu delta_ik g_a . g_b),  A = a - (2 mu/3) I
    (with a = K I it is pfault.physics.elasticity.stiffness's matrix, lambda = K - 2 mu/3); not symmetric where a is
    not a multiple of I. ``shear``: the cells' ``shear_stiffness`` if kept (else computed)."""
    n = len(vol)
    tilde = a - (2.0 / 3.0) * mu[:, None, None] * np.eye(3)
    ag = np.matmul(grad, tilde) * vol[:, None, None]             # (A g_a)_i: A symmetric
    k = ag.reshape(n, 12, 1) * grad.reshape(n, 1, 12)
    k += mu[:, None, None] * (shear_stiffness(grad, vol) if shear is None else shear)
    return k


class CellRows:
    """Adds the element matrices of cells with global dofs ``gdofs`` (n, 12; -1 left out) to a matrix whose
    ownership range is ``owned`` (first, last + 1), row by row: the entries of the rows this rank owns summed per
    matrix entry (the map from the cells' entries to the rows' is found once) and set as whole rows (PETSc's
    MatSetValues merges a sorted row in one pass, where a cell's 12 x 12 block needs 144 searches); the rows other
    ranks own (a vertex this rank shares) as cell blocks, whose owned rows are left out. Paper-size Wuxi's soil
    cells on a rank: ... s instead of ... s per Jacobian."""

    def __init__(self, gdofs: np.ndarray, owned: tuple[int, int]) -> None:
        n = len(gdofs)
        first, last = owned
        rows = np.repeat(gdofs, 12, axis=1).reshape(n, 144).astype(np.int64)
        cols = np.tile(gdofs, (1, 12)).reshape(n, 144).astype(np.int64)
        mine = (rows >= first) & (rows < last) & (cols >= 0)
        width = int(max(cols.max(initial=0), 0)) + 1
        self.take = np.flatnonzero(mine.ravel())
        keys, self.slot = np.unique((rows.ravel()[self.take] - first) * width + cols.ravel()[self.take],
                                    return_inverse=True)
        self.slot = self.slot.ravel()
        self.cols = (keys % width).astype(PETSc.IntType)
        counts = np.bincount(keys // width, minlength=last - first)
        self.indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
        shared = ((rows >= 0) & ((rows < first) | (rows >= last))).any(axis=1)
        self.shared = np.flatnonzero(shared)
        g = gdofs[self.shared]
        self.shared_rows = np.where((g >= first) & (g < last), -1, g).astype(PETSc.IntType)
        self.shared_cols = g.astype(PETSc.IntType)

    def add(self, mat: Any, blocks: np.ndarray) -> None:
        """Add the cells' element matrices ``blocks`` (n, 12, 12) to ``mat``."""
        flat = blocks.reshape(-1)
        values = np.bincount(self.slot, weights=flat[self.take], minlength=len(self.cols))
        mat.setValuesCSR(self.indptr, self.cols, values, addv=ADD)
        if len(self.shared):
            mat.setValuesRCV(self.shared_rows, self.shared_cols, blocks[self.shared].reshape(-1, 144), addv=ADD)
