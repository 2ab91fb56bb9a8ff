"""The cells' forces and tangent stiffness blocks of the soil term, vectorised over cells (NumPy), and their
insertion into PETSc matrices through global indices (-1: a constrained dof, whose entries are left out: the
operator's rows and columns there are the identity's)."""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

ADD = PETSc.InsertMode.ADD_VALUES


def cell_strain(grad: np.ndarray, ue: np.ndarray) -> np.ndarray:
    """The P1 strain (n,3,3) of cells with shape-function gradients ``grad`` (n,4,3) and vertex displacements
    ``ue`` (n,4,3) (pfault.physics.elasticity.strain, with batched matrix products)."""
    h = np.matmul(ue.transpose(0, 2, 1), grad)                   # du_i/dx_j
    return 0.5 * (h + h.transpose(0, 2, 1))


def cell_forces(grad: np.ndarray, vol: np.ndarray, stress: np.ndarray) -> np.ndarray:
    """Nodal forces (n, 12) of a constant symmetric stress per cell (n,3,3): f_a = V sigma g_a."""
    return (np.matmul(grad, stress) * vol[:, None, None]).reshape(len(vol), 12)


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
    tilde = np.array(a, dtype=float, copy=True)
    for i in range(3):
        tilde[:, i, i] -= (2.0 / 3.0) * mu
    ag = np.matmul(grad, tilde) * vol[:, None, None]             # (A g_a)_i: A symmetric
    k = np.multiply(shear_stiffness(grad, vol) if shear is None else shear, mu[:, None, None])
    k += ag.reshape(n, 12, 1) * grad.reshape(n, 1, 12)          # (a batched matmul of 12 x 1 by 1 x 12: slower)
    return k


class CellRows:
    """Adds the element matrices of cells with global dofs ``gdofs`` (n, 12: a vertex's 3 dofs consecutive from a
    multiple of 3, as the DM numbers them), of which ``free`` (n, 12) are not constrained, to a matrix whose ownership
    range is
    ``owned`` (first, last + 1), row by row: the entries of the rows this rank owns summed per matrix entry (the map
    from the cells' entries to the rows' is found once, per 3 x 3 block of a pair of vertices) and set as whole rows
    (PETSc's MatSetValues merges a sorted row in one pass, where a cell's 12 x 12 block takes 144 searches); the rows
    other ranks own (of a vertex this rank shares) as cell blocks, whose owned rows are left out. A constrained dof's
    row and column take zeros (the operator's are the identity's)."""

    def __init__(self, gdofs: np.ndarray, free: np.ndarray, owned: tuple[int, int]) -> None:
        first, last = owned
        block = np.asarray(gdofs, np.int64).reshape(-1, 4, 3)[:, :, 0] // 3           # each vertex's block
        n = len(block)
        mine = (block >= first // 3) & (block < last // 3)                              # (n, 4) rows owned
        rb = np.repeat(block, 4, axis=1).reshape(n, 4, 4)
        cb = np.tile(block, (1, 4)).reshape(n, 4, 4)
        width = int(block.max(initial=0)) + 1
        take = np.repeat(mine, 4, axis=1).reshape(n, 4, 4)
        keys, inverse = np.unique((rb[take] - first // 3) * width + cb[take], return_inverse=True)
        rows, cols = keys // width, keys % width                                        # block pairs, sorted
        per_row = np.bincount(rows, minlength=(last - first) // 3)
        start = np.cumsum(per_row) - per_row                                            # a row block's first pair
        pair = np.zeros((n, 4, 4), np.int64)
        pair[take] = inverse.ravel()
        r = rows[pair]
        # the value slot of the entry (cell, a, i, b, j): 9 start + i 3 npairs + 3 (pair - start) + j
        base = 9 * start[r] + 3 * (pair - start[r])
        i = np.arange(3)[None, None, :, None, None]
        j = np.arange(3)[None, None, None, None, :]
        slot = base[:, :, None, :, None] + i * (3 * per_row[r])[:, :, None, :, None] + j
        free = np.asarray(free, bool)
        f3 = free.reshape(n, 4, 3)
        mask = take[:, :, None, :, None] & f3[:, :, :, None, None] & f3[:, None, None, :, :]
        take = np.flatnonzero(mask.ravel())               # (a constrained dof's entries: zero, left out)
        self.indptr, self.cols = _block_csr(cols, per_row)
        # the sum of the cells' entries into the rows' values as a sparse 0/1 matrix (value slot x cell entry): its
        # product with the cells' blocks adds each slot's entries in the order of the cells, as np.bincount did,
        # at half its cost (a gather in CSR order instead of a scatter)
        from scipy import sparse           # (imported here: only scenes with soils that remember need it)
        self.gather = sparse.csr_matrix((np.ones(len(take)), (slot[mask], take)), shape=(len(self.cols), 144 * n))
        self.gather.sort_indices()
        self.shared = np.flatnonzero((~mine).any(axis=1))
        g = np.where(free[self.shared], gdofs[self.shared], -1)                           # -1: left out
        row_owned = np.repeat(mine[self.shared], 3, axis=1)
        self.shared_rows = np.where(row_owned, -1, g).astype(PETSc.IntType)
        self.shared_cols = g.astype(PETSc.IntType)

    def add(self, mat: Any, blocks: np.ndarray) -> None:
        """Add the cells' element matrices ``blocks`` (n, 12, 12) to ``mat``."""
        values = self.gather @ blocks.reshape(-1)
        mat.setValuesCSR(self.indptr, self.cols, values, addv=ADD)
        if len(self.shared):
            mat.setValuesRCV(self.shared_rows, self.shared_cols, blocks[self.shared].reshape(-1, 144), addv=ADD)


def _block_csr(cols: np.ndarray, per_row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point CSR (indptr, column indices) of the 3 x 3 blocks whose column blocks ``cols`` are listed row block
    by row block (``per_row`` of them each, sorted): each row block's three rows take 3 columns per column block."""
    row_block = np.repeat(np.arange(len(per_row)), per_row)
    pos_in_row = np.arange(len(cols)) - np.repeat(np.cumsum(per_row) - per_row, per_row)
    offset = 9 * (np.cumsum(per_row) - per_row)
    # value index of (pair k, row i, column j): offset[rb] + i * 3 n[rb] + 3 pos + j
    i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    index = (offset[row_block][:, None, None] + i[None] * (3 * per_row[row_block])[:, None, None]
             + 3 * pos_in_row[:, None, None] + j[None]).ravel()
    out = np.empty(9 * len(cols), PETSc.IntType)
    out[index] = (3 * np.repeat(cols, 9).reshape(-1, 3, 3) + j[None]).ravel()
    counts = np.repeat(3 * per_row, 3)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
    return indptr, out
