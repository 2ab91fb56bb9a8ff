"""Named subfields on the DMPlex -> one PetscSection.

Field 0 ``displacement`` lives on vertices, 3 dofs per side (a split fault vertex carries one side per piece of
its star: two where a fault passes, three or more at a junction, pfault.mesh.fault).
Field 1 ``lagrange_multiplier_fault`` (only when the scene has faults) lives on the cells that own
fault faces, 3 dofs (normal, two tangential tractions) per fault face.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

if TYPE_CHECKING:
    from .mesh.distributed import LocalMesh

DISPLACEMENT = "displacement"
LAGRANGE = "lagrange_multiplier_fault"


@dataclass
class DofMap:
    section: PETSc.Section
    vert_offset: np.ndarray      # (nv,) local offset of each vertex's first dof
    vert_sides: np.ndarray       # (nv,) displacement sides (pieces of the star) per vertex
    cell_offset: np.ndarray      # (nc,) local offset of each cell's multiplier dofs (-1: none)
    cell_dofs: np.ndarray        # (nc, 12) local displacement dofs of each cell
    n_local: int
    fields: tuple
    max_sides: int = 2           # the most sides of any vertex on any rank, at least 2 (output columns)

    def field_mask(self, name: str) -> np.ndarray:
        """Boolean mask of this rank's local dofs of the field ``name`` (DISPLACEMENT: the vertices' dofs, every
        side; LAGRANGE: the cells' multipliers)."""
        n = 3 * self.vert_sides
        vertex = np.zeros(self.n_local, dtype=bool)
        within = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        vertex[np.repeat(self.vert_offset, n) + within] = True
        return vertex if name == DISPLACEMENT else ~vertex

    def vertex_dofs(self, side: int = 0) -> np.ndarray:
        """(nv, 3) local dofs of the given side (falls back to side 0 where a vertex has fewer sides)."""
        base = self.vert_offset + 3 * np.where(self.vert_sides > side, side, 0)
        return base[:, None] + np.arange(3)


def build(mesh: LocalMesh, vert_sides: np.ndarray | None = None, cell_side: np.ndarray | None = None,
          cell_multipliers: np.ndarray | None = None) -> DofMap:
    """Create the section and set it on the DM.

    vert_sides: (nv,) number of displacement sides per vertex (default 1)
    cell_side: (nc, 4) which side (0 .. vert_sides - 1) each cell uses at each of its vertices (default 0)
    cell_multipliers: (nc,) number of fault faces whose multipliers a cell carries (default none)
    """
    dm = mesh.dm
    nc, nv = len(mesh.cells), len(mesh.coords)
    vert_sides = np.ones(nv, np.int64) if vert_sides is None else np.asarray(vert_sides, np.int64)
    cell_side = np.zeros((nc, 4), np.int64) if cell_side is None else np.asarray(cell_side, np.int64)
    with_lm = cell_multipliers is not None
    cell_lm = np.zeros(nc, np.int64) if cell_multipliers is None else np.asarray(cell_multipliers, np.int64)
    fields = (DISPLACEMENT, LAGRANGE) if with_lm else (DISPLACEMENT,)
    sec = PETSc.Section().create(comm=dm.getComm())
    sec.setNumFields(len(fields))
    for f, name in enumerate(fields):
        sec.setFieldName(f, name)
        sec.setFieldComponents(f, 3)
    p_start, p_end = dm.getChart()
    sec.setChart(p_start, p_end)
    # PetscSection has no array setter in petsc4py 3.18: one call per point that carries dofs
    vdofs = 3 * vert_sides
    for v, n in zip(range(mesh.v_start, mesh.v_start + nv), vdofs.tolist()):
        sec.setDof(v, n)
        sec.setFieldDof(v, 0, n)
    if with_lm:
        for c in np.nonzero(cell_lm)[0].tolist():
            n = 3 * int(cell_lm[c])
            sec.setDof(c, n)
            sec.setFieldDof(c, 1, n)
    sec.setUp()
    dm.setSection(sec)
    # offsets are laid out in chart order (cells first, then vertices)
    counts = np.concatenate([3 * cell_lm, vdofs])
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    cell_offset = np.where(cell_lm > 0, offsets[:nc], -1)
    vert_offset = offsets[nc:]
    if nv:
        assert sec.getOffset(mesh.v_start + nv - 1) == vert_offset[-1]
    base = vert_offset[mesh.cells] + 3 * np.where(vert_sides[mesh.cells] > 1, cell_side, 0)
    cell_dofs = (base[:, :, None] + np.arange(3)).reshape(nc, 12)
    return DofMap(section=sec, vert_offset=vert_offset, vert_sides=vert_sides, cell_offset=cell_offset,
                  cell_dofs=cell_dofs, n_local=int(counts.sum()), fields=fields,
                  max_sides=max(2, dm.getComm().tompi4py().allreduce(int(vert_sides.max(initial=1)), op=MPI.MAX)))


@dataclass(frozen=True)
class FaceRows:
    """The fault faces this rank owns (those whose minus cell it has: the cell that carries the face's multipliers),
    in serial order: their serial ids ``face``, local multiplier dofs ``lm_dofs`` (nf, 3: the minus cell's 3 per fault
    face it is the minus cell of, in local-face order); ``total``: the fault faces of the whole mesh (0 without
    faults)."""
    face: np.ndarray
    lm_dofs: np.ndarray
    total: int


def face_rows(mesh: LocalMesh, dofmap: DofMap, total: int) -> FaceRows:
    cells, lfaces = np.nonzero(mesh.cell_fault_face >= 0)
    fid = mesh.cell_fault_face[cells, lfaces]
    order = np.argsort(fid)
    cell, lface = cells[order], lfaces[order]
    at = mesh.cell_fault_face[cell] >= 0
    slot = (at & (np.arange(4)[None, :] < lface[:, None])).sum(axis=1)
    lm = dofmap.cell_offset[cell][:, None] + 3 * slot[:, None] + np.arange(3)
    return FaceRows(fid[order].astype(np.int64), lm.reshape(-1, 3), int(total))
