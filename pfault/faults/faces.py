"""The fault faces this rank owns on the distributed mesh: their geometry, their cells and dofs on both sides and
their multipliers, and the exchange of per-face values between ranks.

Every fault face is handled by the rank that owns its minus cell, and the partition keeps its plus cell on the same
rank (pfault.mesh.distributed): both cells, with their face bubbles (pfault.faults.bubbles), are local, so the
interface element and its condensation are local. The laws that act on the faces are pfault.faults.interface's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..errors import InputError
from ..mesh.serial import TET_FACES, face_keys
from ..physics import elasticity as el
from . import contact as ct

ADD = PETSc.InsertMode.ADD_VALUES


@dataclass(frozen=True)
class FaceSides:
    """The two cells of each owned face (local ids, columns minus and plus) and the face's local face in each."""
    cell: np.ndarray        # (nf, 2)
    lface: np.ndarray       # (nf, 2)


@dataclass(frozen=True)
class FaceDofs:
    """Displacement dofs of the face's vertices on both sides, those of the piece each of its two cells uses at
    each vertex (pfault.mesh.fault; the same dofs at a tip): local ``u`` (nf, 18, minus side first) and
    global ``g_u``, whether each is free (``u_free``: constrained dofs take no force), the jump's sign of each
    (plus - minus), and the multipliers' global dofs ``g_lm``."""
    u: np.ndarray
    g_u: np.ndarray
    u_free: np.ndarray
    sign: np.ndarray
    g_lm: np.ndarray

    @property
    def minus(self) -> np.ndarray:
        return self.u[:, :9].reshape(-1, 3, 3)

    @property
    def plus(self) -> np.ndarray:
        return self.u[:, 9:].reshape(-1, 3, 3)


class FaultFaces:
    """The owned fault faces (serial ids ``face``, ordered; ``nf`` of ``nf_total``): minus cell ``cell``, both
    cells ``sides``, vertices, area, unit normal (minus -> plus) and local frames ``R``, the fault of each face and
    whether it is a Lagrange face, the Young's modulus of the minus cell (from ``young``, per local cell), the displacement dofs of both sides ``dofs`` and
    the local multiplier dofs ``lm_dofs`` (every face carries its traction as 3 multipliers)."""

    def __init__(self, mesh: Any, dofmap: Any, settings: list, fault_id: np.ndarray, young: np.ndarray,
                 bc_local: np.ndarray, lgmap: Any) -> None:
        self.settings = settings
        self.mpi = mesh.dm.getComm().tompi4py()
        self.nf_total = len(fault_id)
        cells, lfaces = np.nonzero(mesh.cell_fault_face >= 0)
        fid = mesh.cell_fault_face[cells, lfaces]
        order = np.argsort(fid)
        self.face = fid[order]
        self.cell = cells[order]
        nf = self.nf = len(self.face)
        self.fault = fault_id[self.face]
        self.verts = mesh.cells[self.cell[:, None], TET_FACES[lfaces[order]]]
        self.sides, together = _sides(mesh, self.cell, lfaces[order], self.verts)
        if not self.mpi.allreduce(together, op=MPI.LAND):
            raise InputError("a fault face's two cells are on different ranks; partition with PT-Scotch or "
                             "ParMETIS (remove -petscpartitioner_type) or run on one rank")
        an = el.triangle_area_normal(mesh.coords[self.verts])   # outward normal of the minus cell: minus -> plus
        self.area = np.linalg.norm(an, axis=1)
        self.normal = an / np.maximum(self.area, 1e-300)[:, None]
        self.R = ct.local_frames(self.normal) if nf else np.zeros((0, 3, 3))
        self.lagrange = np.array([s.method == "lagrange" for s in settings])[self.fault]
        self.young = young[self.cell]
        self.lm_dofs = self._multiplier_dofs(mesh, dofmap)
        self.dofs = self._dofs(mesh.cells, dofmap, bc_local, lgmap)

    @property
    def h(self) -> np.ndarray:
        """Size of each face (m): the square root of its area."""
        return np.sqrt(self.area)

    def _multiplier_dofs(self, mesh: Any, dofmap: Any) -> np.ndarray:
        """Local multiplier dofs (nf, 3): the minus cell carries 3 dofs per fault face it is the minus cell of
        (pfault.model), in local-face order."""
        slot = np.zeros(self.nf, np.int64)
        if self.nf:
            at = mesh.cell_fault_face[self.cell] >= 0
            slot = (at & (np.arange(4)[None, :] < self.sides.lface[:, :1])).sum(axis=1)
        return dofmap.cell_offset[self.cell][:, None] + 3 * slot[:, None] + np.arange(3)

    def _dofs(self, cells: np.ndarray, dofmap: Any, bc_local: np.ndarray, lgmap: Any) -> FaceDofs:
        nf = self.nf
        cd = dofmap.cell_dofs.reshape(-1, 4, 3)
        minus = cd[self.cell[:, None], TET_FACES[self.sides.lface[:, 0]]]             # (nf,3,3)
        plus_cell = self.sides.cell[:, 1]
        at = np.argmax(cells[plus_cell][:, None, :] == self.verts[:, :, None], axis=2)  # (nf,3) local vertex
        plus = cd[plus_cell[:, None], at]                                               # (nf,3,3)
        u = np.concatenate([minus.reshape(nf, 9), plus.reshape(nf, 9)], axis=1)
        idx = PETSc.IntType
        g_u = lgmap.apply(u.ravel().astype(idx)).reshape(nf, 18) if nf else np.zeros((0, 18), idx)
        g_lm = lgmap.apply(self.lm_dofs.ravel().astype(idx)).reshape(nf, 3) if nf else np.zeros((0, 3), idx)
        free = ~bc_local[u] if nf else np.zeros((0, 18), bool)
        return FaceDofs(u, g_u, free, np.concatenate([-np.ones(9), np.ones(9)]), g_lm)

    # -- kinematics ----------------------------------------------------------------------------
    def jumps(self, u_loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Face-average jump of the P1 displacements, global (nf,3) and local (nf,3)."""
        g = (u_loc[self.dofs.plus] - u_loc[self.dofs.minus]).mean(axis=1)
        return g, np.einsum("nij,nj->ni", self.R, g)

    def insert_pattern(self, J: Any) -> None:
        """Insert explicit zeros where the interface blocks within the faces' vertices go (for exact
        preallocation; the bubbles' blocks beyond them are pfault.faults.interface's pattern)."""
        n, d = self.nf, self.dofs
        if n:
            J.setValuesRCV(d.g_u, d.g_lm, np.zeros((n, 54)), addv=ADD)
            J.setValuesRCV(d.g_lm, d.g_u, np.zeros((n, 54)), addv=ADD)
            J.setValuesRCV(d.g_lm, d.g_lm, np.zeros((n, 9)), addv=ADD)


def _sides(mesh: Any, cell: np.ndarray, lface: np.ndarray, verts: np.ndarray) -> tuple[FaceSides, bool]:
    """The minus and plus cells of the faces (minus cells ``cell`` with local faces ``lface``, vertices ``verts``):
    the plus cell is the other local cell with the face's three vertices (a split vertex is one mesh point for
    both sides); False where a plus cell is not on this rank."""
    nf = len(cell)
    z = np.zeros((0, 2), np.int64)
    if nf == 0:
        return FaceSides(z, z), True
    nv = len(mesh.coords)
    keys = face_keys(mesh.cells[:, TET_FACES].reshape(-1, 3), nv)
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    want = face_keys(verts, nv)
    lo, hi = np.searchsorted(ks, want, "left"), np.searchsorted(ks, want, "right")
    if np.any(hi - lo != 2):
        return FaceSides(z, z), False       # a plus cell on another rank
    a, b = order[lo], order[lo + 1]
    other = np.where(a // 4 == cell, b, a)
    return FaceSides(np.column_stack([cell, other // 4]), np.column_stack([lface, other % 4])), True
