"""The fault faces this rank owns on the distributed mesh: their geometry, their dofs on both sides and their
multipliers, and the exchange of per-face values between ranks.

Every fault face is handled by the rank that owns its minus cell; the face's vertices, with both sides'
displacement dofs, are in that cell's closure, so the interface element is local. Only the stabilisation
couples neighbouring faces, which may sit on other ranks: their values are gathered on every rank (the fault is
a surface: O(faces) data). The laws that act on the faces are pfault.faults.interface's.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

from ..mesh.serial import TET_FACES
from ..physics import elasticity as el
from . import contact as ct

ADD = PETSc.InsertMode.ADD_VALUES


class FaultFaces:
    """The owned fault faces (serial ids ``face``, ordered; ``nf`` of ``nf_total``): minus cell and local face,
    vertices, area, unit normal (minus -> plus) and local frames ``R``, the fault of each face and whether it is a
    Lagrange face, the Young's modulus of the minus cell (from ``young``, per local cell), the displacement dofs of
    both sides (local ``u_dofs``, global ``g_u``) and the multiplier dofs (``lm_dofs``, ``g_lm``; -1 on penalty
    faces)."""

    def __init__(self, mesh: Any, dofmap: Any, settings: list, fault_id: np.ndarray, young: np.ndarray,
                 bc_local: np.ndarray, lgmap: Any) -> None:
        self.settings = settings
        self.mpi = mesh.dm.getComm().tompi4py()
        self.nf_total = len(fault_id)
        cells, lfaces = np.nonzero(mesh.cell_fault_face >= 0)
        fid = mesh.cell_fault_face[cells, lfaces]
        order = np.argsort(fid)
        self.face = fid[order]
        self.cell, self.lface = cells[order], lfaces[order]
        nf = self.nf = len(self.face)
        self.fault = fault_id[self.face]
        self.verts = mesh.cells[self.cell[:, None], TET_FACES[self.lface]]
        an = el.triangle_area_normal(mesh.coords[self.verts])   # outward normal of the minus cell: minus -> plus
        self.area = np.linalg.norm(an, axis=1)
        self.normal = an / np.maximum(self.area, 1e-300)[:, None]
        self.R = ct.local_frames(self.normal) if nf else np.zeros((0, 3, 3))
        self.lagrange = np.array([s.method == "lagrange" for s in settings])[self.fault]
        self.has_lagrange = any(s.method == "lagrange" for s in settings)
        self.h = np.sqrt(self.area)
        self.young = young[self.cell]
        self._dofs(mesh, dofmap, bc_local, lgmap, fault_id)
        self._setup_gather()
        self.pos = np.full(self.nf_total, -1)       # owned index of each serial face (-1: another rank's)
        self.pos[self.face] = np.arange(nf)

    def _dofs(self, mesh, dofmap, bc_local, lgmap, fault_id):
        nf = self.nf
        self.n_local = dofmap.n_local
        cd = dofmap.cell_dofs.reshape(-1, 4, 3)
        self.minus_dofs = cd[self.cell[:, None], TET_FACES[self.lface]]             # (nf,3,3)
        self.plus_dofs = dofmap.vertex_dofs(1)[self.verts]                            # (nf,3,3)
        # slot of each Lagrange face in its cell's multiplier block (the cell carries 3 dofs per Lagrange face
        # it is the minus cell of, pfault.simulation): its Lagrange faces in local-face order
        lag_fault = np.array([st.method == "lagrange" for st in self.settings])
        slot = np.zeros(nf, np.int64)
        if nf:
            fid = mesh.cell_fault_face[self.cell]
            lag_at = (fid >= 0) & lag_fault[fault_id[np.maximum(fid, 0)]]
            slot = (lag_at & (np.arange(4)[None, :] < self.lface[:, None])).sum(axis=1)
        self.lm_dofs = np.where(self.lagrange[:, None], dofmap.cell_offset[self.cell][:, None] + 3 * slot[:, None]
                                + np.arange(3), -1)
        self.u_dofs = np.concatenate([self.minus_dofs.reshape(nf, 9), self.plus_dofs.reshape(nf, 9)], axis=1)
        self.sign = np.concatenate([-np.ones(9), np.ones(9)])                        # jump = plus - minus
        idx = PETSc.IntType
        self.g_u = lgmap.apply(self.u_dofs.ravel().astype(idx)).reshape(nf, 18) if nf else np.zeros((0, 18), idx)
        self.g_lm = lgmap.apply(self.lm_dofs.ravel().astype(idx)).reshape(nf, 3) if nf else np.zeros((0, 3), idx)
        self.u_mask = ~bc_local[self.u_dofs] if nf else np.zeros((0, 18), bool)       # constrained dofs get no force

    # -- data exchange ------------------------------------------------------------------------
    def _setup_gather(self):
        ids = np.concatenate(self.mpi.allgather(self.face)) if self.nf_total else np.zeros(0, np.int64)
        self.all_ids = ids.astype(np.int64)
        self.all_g_lm = np.zeros((self.nf_total, 3), np.int64)
        glm = self.mpi.allgather(self.g_lm.astype(np.int64))
        if self.nf_total:
            self.all_g_lm[self.all_ids] = np.concatenate(glm)

    def gather_faces(self, values):
        """Per-owned-face arrays (nf, k) -> (nf_total, k) in serial face order on every rank."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        k = values.shape[1] if values.ndim > 1 else 1
        parts = self.mpi.allgather(values.reshape(self.nf, k))
        out = np.zeros((self.nf_total, k))
        if self.nf_total:
            out[self.all_ids] = np.concatenate(parts)
        return out

    # -- kinematics ----------------------------------------------------------------------------
    def jumps(self, u_loc):
        """Face-average jump, global (nf,3) and local (nf,3)."""
        g = (u_loc[self.plus_dofs] - u_loc[self.minus_dofs]).mean(axis=1)
        return g, np.einsum("nij,nj->ni", self.R, g)

    def insert_pattern(self, J):
        """Insert explicit zeros where the interface blocks go (for exact preallocation)."""
        lag = np.nonzero(self.lagrange)[0]
        n = len(lag)
        if n:
            J.setValuesRCV(self.g_u[lag], self.g_lm[lag], np.zeros((n, 54)), addv=ADD)
            J.setValuesRCV(self.g_lm[lag], self.g_u[lag], np.zeros((n, 54)), addv=ADD)
            J.setValuesRCV(self.g_lm[lag], self.g_lm[lag], np.zeros((n, 9)), addv=ADD)
        pen = np.nonzero(~self.lagrange)[0]
        if len(pen):   # both sides' dofs of a penalty face
            J.setValuesRCV(self.g_u[pen], self.g_u[pen], np.zeros((len(pen), 324)), addv=ADD)
