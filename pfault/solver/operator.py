"""The constant operator K of the equations (pfault.solver.equations): the elastic stiffness of the cells plus the
terms' constant parts (a fault's condensed face bubbles), with the pattern of every entry the terms' Jacobians add
(their ``pattern``), as AIJ with block size 3 (AMG reads the block size from the matrix).

Where every dof comes in aligned triples (the DM's local-to-global map has block size 3) the matrix is BAIJ with
3x3 blocks, preallocated with exactly the blocks the cells and the terms touch, filled block by block and converted
once to AIJ, which every solver takes (GAMG takes no BAIJ). A cell adds 16 3x3 blocks, each found once, where an
AIJ matrix looks up 144 entries one by one (1M-tet box, 2 ranks: insertion 0.3 s instead of 0.7 s, conversion
0.16 s). A scene without terms takes the DM's own matrix (block size 3 there); the DM's matrix of a scene with
faults has block size 1 (its points carry 3 or 6 dofs: a split vertex 6), filled entry by entry and then extended
by the terms' pattern: paper-size Wuxi, 2 ranks, two side-by-side pairs, 1.24-1.29 s that way, 0.71-0.74 s here.
The pattern holds fewer explicit zeros than the DM's adjacency gave (a face's multipliers reach what the interface
blocks couple, not every point of its cells' closures), which ILU(0) takes as its fill: pfault's solver files use
no ILU; GMRES + ILU(0) on a stuck fault's Jacobian needs one level of fill (``-pc_factor_levels 1``) to converge as
before (tests/verification/test_faults.py, the penalty conditioning).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc


def build_operator(dm: Any, assembler: Any, dofmap: Any, terms: tuple) -> Any:
    """K (assembled AIJ, block size 3 with terms, its local-to-global map set, new nonzeros an error) of the cells
    of ``assembler`` (pfault.assembly.elastic.ElasticAssembler) and the ``terms`` on the DM ``dm``."""
    lgmap = dm.getLGMap()
    if terms and lgmap.getBlockSize() == 3:
        return build_blocked(dm, lgmap, assembler, dofmap, terms)
    return build_from_dm(dm, assembler, terms)


def build_blocked(dm: Any, lgmap: Any, assembler: Any, dofmap: Any, terms: tuple) -> Any:
    """K as BAIJ with 3x3 blocks preallocated with exactly the blocks the cells and the terms touch (the terms'
    constant parts and their further Jacobian entries), explicit zeros where nothing is added yet; then AIJ.
    ``lgmap``: the DM's local-to-global map, block size 3. Collective."""
    comm = dm.getComm()
    g = dm.getGlobalVec()
    n, N = g.getLocalSize(), g.getSize()
    start = g.getOwnershipRange()[0]
    dm.restoreGlobalVec(g)
    record = BlockPattern(lgmap.getBlockIndices(), lgmap.getIndices())
    cells = record.block_of_local[dofmap.cell_dofs[:, 0::3] // 3]
    record.add(cells, cells)
    for term in terms:
        term.add_operator(record, True)
        rows, cols = term.pattern()
        record.add(np.asarray(rows, np.int64)[:, None] // 3, np.asarray(cols, np.int64)[:, None] // 3)
    mpi = comm.tompi4py()
    rows, cols = _to_owners(mpi, np.asarray(mpi.allgather(start // 3) + [N // 3], np.int64), *record.pairs())
    nb, NB = n // 3, N // 3
    key = np.unique((rows - start // 3) * NB + cols)
    ptr = np.concatenate([[0], np.cumsum(np.bincount(key // NB, minlength=nb))]).astype(PETSc.IntType)
    Kb = PETSc.Mat().createBAIJ(size=((n, N), (n, N)), bsize=3, csr=(ptr, (key % NB).astype(PETSc.IntType)),
                                comm=comm)
    Kb.setLGMap(lgmap, lgmap)
    Kb.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    assembler.add_stiffness(Kb, blocked=True)
    for term in terms:
        term.add_operator(Kb, True)
    Kb.assemble()
    K = Kb.convert(PETSc.Mat.Type.AIJ)      # in place; the conversion drops the local-to-global map
    K.setLGMap(lgmap, lgmap)
    K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return K


def build_from_dm(dm: Any, assembler: Any, terms: tuple) -> Any:
    """K in the DM's own matrix (BAIJ, blocked where its local-to-global map has block size 3), then AIJ extended
    by the terms' pattern with block size 3. Collective."""
    dm.setMatType(PETSc.Mat.Type.BAIJ)
    try:
        Kb = dm.createMatrix()     # (petsc4py 3.18 has no DMGetMatType: pfault's DMs use AIJ)
    finally:
        dm.setMatType(PETSc.Mat.Type.AIJ)
    Kb.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    blocked = Kb.getLGMap()[0].getBlockSize() == 3
    assembler.add_stiffness(Kb, blocked=blocked)
    for term in terms:
        term.add_operator(Kb, blocked)      # a fault's condensed face bubbles, its faces' pattern
    Kb.assemble()
    lgmap = Kb.getLGMap()
    K = Kb.convert(PETSc.Mat.Type.AIJ)      # in place; the conversion drops the local-to-global map
    K.setLGMap(*lgmap)
    K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    if not terms:
        return K
    # rebuilt with the pattern of the terms' blocks (a fault's bubbles reach beyond the cells' closures: a face's
    # row reaches the plus cell's fourth vertex, a cell's rows the multipliers of its faces, a face's row those
    # of the faces sharing a cell) and block size 3 (every point carries 3, 6 or 3k dofs: AMG reads the block
    # size from the matrix)
    pairs = [term.pattern() for term in terms]
    rows, cols = _to_owners(K.getComm().tompi4py(), np.asarray(K.getOwnershipRanges()),
                            np.concatenate([p[0] for p in pairs]), np.concatenate([p[1] for p in pairs]))
    K1 = _extend_pattern(K, rows, cols, bs=3)
    K.destroy()
    return K1


class BlockPattern:
    """Stands in for the operator while the cells and the terms add to it: the 3x3 blocks they touch, as global
    block indices (``block_of_local``: of the local blocks; ``global_of_local``: of the local dofs), not their
    values. Takes the insertions a term makes (pfault.solver.terms, ``add_operator``)."""

    def __init__(self, block_of_local: np.ndarray, global_of_local: np.ndarray) -> None:
        self.block_of_local = np.asarray(block_of_local, np.int64)
        self.global_of_local = np.asarray(global_of_local, np.int64)
        self._rows: list = []
        self._cols: list = []

    def add(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Every (rows[k, i], cols[k, j]) pair (global block indices; negative ones are left out, as PETSc does)."""
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        if rows.size == 0 or cols.size == 0:
            return
        rows, cols = rows.reshape(len(rows), -1), cols.reshape(len(cols), -1)
        r = np.repeat(rows, cols.shape[1], axis=1).ravel()
        c = np.tile(cols, (1, rows.shape[1])).ravel()
        keep = (r >= 0) & (c >= 0)
        self._rows.append(r[keep])
        self._cols.append(c[keep])

    def setValuesBlockedLocalRCV(self, R: Any, C: Any, V: Any, addv: Any = None) -> None:  # noqa: N802 (PETSc's)
        self.add(_mapped(self.block_of_local, R), _mapped(self.block_of_local, C))

    def setValuesLocalRCV(self, R: Any, C: Any, V: Any, addv: Any = None) -> None:  # noqa: N802
        self.add(_mapped(self.global_of_local, R) // 3, _mapped(self.global_of_local, C) // 3)

    def setValuesRCV(self, R: Any, C: Any, V: Any, addv: Any = None) -> None:  # noqa: N802
        self.add(np.asarray(R, np.int64) // 3, np.asarray(C, np.int64) // 3)

    def pairs(self) -> tuple[np.ndarray, np.ndarray]:
        if not self._rows:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(self._rows), np.concatenate(self._cols)


def _mapped(table: np.ndarray, idx: Any) -> np.ndarray:
    """table[idx], -1 where idx is negative (a left-out entry, as PETSc takes it)."""
    idx = np.asarray(idx, np.int64)
    return np.where(idx >= 0, table[np.maximum(idx, 0)], -1)


def _to_owners(comm: Any, ranges: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global (row, col) pairs of any rank's rows -> those of the rows this rank owns, from all ranks (``comm``: an
    mpi4py communicator; ``ranges``: the first row of every rank and the number of rows)."""
    if comm.size == 1:
        return rows, cols
    owner = np.searchsorted(ranges, rows, side="right") - 1
    parts = comm.alltoall([(rows[owner == r], cols[owner == r]) for r in range(comm.size)])
    return (np.concatenate([p[0] for p in parts]).astype(np.int64),
            np.concatenate([p[1] for p in parts]).astype(np.int64))


def _extend_pattern(K0: Any, rows: np.ndarray, cols: np.ndarray, bs: int = 1) -> Any:
    """A new AIJ matrix (block size bs) with K0's values and pattern plus explicit zeros at (rows, cols) (owned
    rows)."""
    rstart, rend = K0.getOwnershipRange()
    indptr, indices, values = K0.getValuesCSR()
    nrows = rend - rstart
    rows = np.asarray(rows, np.int64) - rstart
    if len(rows) and (rows.min() < 0 or rows.max() >= nrows):
        raise RuntimeError("extra pattern rows must be owned")
    ncols = K0.getSize()[1]
    # K0's rows are sorted and without repeats (an assembled AIJ matrix), so its keys row * ncols + col are
    # sorted: the new entries are placed by binary search instead of sorting all entries again (paper-size
    # calibrated Queretaro, with the BAIJ insertion: the operator's build 1.0-1.1 s instead of 1.6-2.3 s)
    key = np.repeat(np.arange(nrows, dtype=np.int64), np.diff(indptr)) * ncols + indices
    extra = np.unique(rows * ncols + np.asarray(cols, np.int64))
    pos = np.searchsorted(key, extra)
    found = pos < len(key)
    found[found] = key[pos[found]] == extra[found]
    extra, pos = extra[~found], pos[~found]
    c_u = np.insert(indices, pos, (extra % ncols).astype(indices.dtype)).astype(PETSc.IntType)
    vals = np.insert(values, pos, 0.0)
    counts = np.diff(indptr) + np.bincount(extra // ncols, minlength=nrows)
    ptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
    K = PETSc.Mat().createAIJ(size=K0.getSizes(), bsize=bs, csr=(ptr, c_u, vals), comm=K0.getComm())
    K.setLGMap(*K0.getLGMap())
    K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    K.assemble()
    return K
