"""Assembly of the elastic operator and loads, vectorised over cells and batched into PETSc."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from petsc4py import PETSc

from ..mesh.serial import TET_FACES
from ..physics import elasticity as el

if TYPE_CHECKING:
    from ..fields import DofMap
    from ..mesh.distributed import LocalMesh
    from ..materials.properties import CellProperties

CHUNK = 4096     # cells per kernel batch: element matrices of a batch stay in cache


class ElasticAssembler:
    def __init__(self, mesh: LocalMesh, dofmap: DofMap, props: CellProperties,
                 stiffness: np.ndarray | None = None) -> None:
        """``props``: the material properties of the local cells; ``stiffness``: the cells whose stiffness the
        operator holds (None: all); the others (the materials with memory, pfault.soils) enter it with zero
        stiffness, which keeps their pattern: their term adds their stiffness."""
        self.mesh = mesh
        self.dofmap = dofmap
        self.stiffness = stiffness
        self.lam, self.mu = el.lame(props.young_modulus, props.poisson_ratio)
        self.alpha = props.biot_coefficient
        self.density = props.density
        self.grad, self.vol = el.tet_geometry(mesh.coords[mesh.cells])
        if len(self.vol) and self.vol.min() <= 0:
            raise RuntimeError("inverted tetrahedron after distribution")
        self.centroids = mesh.coords[mesh.cells].mean(axis=1)

    # -- operator ----------------------------------------------------------------------------
    def add_stiffness(self, mat: PETSc.Mat, blocked: bool = False) -> None:
        """Add element stiffness matrices into ``mat`` (local numbering), in batches of CHUNK cells; ``blocked``:
        as 3x3 blocks of the vertices' local block indices (a matrix whose local-to-global map has block size
        3; a vertex's 3 dofs are consecutive and start at a multiple of 3)."""
        dofs = self.dofmap.cell_dofs
        idx = (dofs[:, 0::3] // 3 if blocked else dofs).astype(PETSc.IntType)
        insert = mat.setValuesBlockedLocalRCV if blocked else mat.setValuesLocalRCV
        lam, mu = self.lam, self.mu
        if self.stiffness is not None:
            lam, mu = np.where(self.stiffness, lam, 0.0), np.where(self.stiffness, mu, 0.0)
        for s in range(0, len(dofs), CHUNK):
            e = slice(s, s + CHUNK)
            ke = el.stiffness(self.grad[e], self.vol[e], lam[e], mu[e])
            insert(idx[e], idx[e], ke.reshape(len(ke), 144), addv=PETSc.InsertMode.ADD_VALUES)

    # -- loads (local arrays, to be added with localToGlobal) ---------------------------------
    def scatter_cell_forces(self, fe: np.ndarray, out: np.ndarray) -> None:
        """Add nodal forces fe (nc,4,3) into the local array ``out`` (bincount, no Python loop)."""
        out += np.bincount(self.dofmap.cell_dofs.ravel(), weights=fe.reshape(-1), minlength=len(out))

    def pore_pressure_load(self, dp: np.ndarray, out: np.ndarray) -> None:
        self.scatter_cell_forces(el.pore_pressure_force(self.grad, self.vol, self.alpha * dp), out)

    def gravity_load(self, g: float, out: np.ndarray) -> None:
        b = np.zeros((len(self.vol), 3))
        b[:, 2] = -self.density * g
        self.scatter_cell_forces(el.body_force(self.vol, b), out)

    def traction_load(self, tractions: Sequence[Sequence[float]], out: np.ndarray) -> None:
        """Constant tractions on tagged boundary faces; tractions[tag] = (tx, ty, tz)."""
        tag = self.mesh.cell_face_tag
        cell, lface = np.nonzero(tag >= 0)
        if len(cell) == 0:
            return
        tri = self.mesh.cells[cell[:, None], TET_FACES[lface]]
        area = np.linalg.norm(el.triangle_area_normal(self.mesh.coords[tri]), axis=1)
        t = np.asarray(tractions, float)[tag[cell, lface]]
        local = self.dofmap.cell_dofs.reshape(-1, 4, 3)[cell[:, None], TET_FACES[lface]]  # (nf, 3, 3)
        f = np.repeat((area[:, None] * t / 3.0)[:, None, :], 3, axis=1)
        out += np.bincount(local.ravel(), weights=f.ravel(), minlength=len(out))

    # -- post-processing ----------------------------------------------------------------------
    def cell_displacements(self, u_local: np.ndarray) -> np.ndarray:
        return u_local[self.dofmap.cell_dofs].reshape(-1, 4, 3)

    def effective_stress(self, u_local: np.ndarray) -> np.ndarray:
        """Incremental effective stress C:eps(u) per cell (nc,3,3)."""
        return el.stress(el.strain(self.grad, self.cell_displacements(u_local)), self.lam, self.mu)
