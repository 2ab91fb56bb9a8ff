"""The fault faces' blocks in the PETSc matrices and their forces on the displacement rows: where the fault
term's law derivatives (pfault.faults.term) become matrix entries, through the faces' dofs (pfault.faults.faces)
and the condensed face bubbles (pfault.faults.bubbles)."""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

from .bubbles import CellBubbles
from .faces import FaultFaces

ADD = PETSc.InsertMode.ADD_VALUES


class FaceBlocks:
    """The matrix blocks and forces of a rank's fault faces (``faces``) and their cells' bubbles (``bubbles``)."""

    def __init__(self, faces: FaultFaces, bubbles: CellBubbles) -> None:
        self.faces, self.bubbles = faces, bubbles

    def add_stiffness(self, K: Any, blocked: bool) -> None:
        """Add what the condensed bubbles add to their cells' stiffness, -K_ub K_bb^-1 K_bu, to K (local numbering;
        ``blocked``: as 3x3 blocks, as pfault.assembly.elastic's ``add_stiffness``)."""
        dofs, ke = self.bubbles.stiffness()
        if len(dofs) == 0:
            return
        if blocked:
            idx = (dofs[:, 0::3] // 3).astype(PETSc.IntType)
            K.setValuesBlockedLocalRCV(idx, idx, ke.reshape(len(ke), 144), addv=ADD)
        else:
            idx = dofs.astype(PETSc.IntType)
            K.setValuesLocalRCV(idx, idx, ke.reshape(len(ke), 144), addv=ADD)

    def traction_forces(self, dt: np.ndarray, out: np.ndarray) -> None:
        """Add to the local array ``out`` the forces on the displacement dofs of the traction changes dt (nf, 3;
        the initial traction is in equilibrium with the initial stress): minus side -(A/3) R^T dt, plus side
        +(A/3) R^T dt; and those through the bubbles."""
        fc = self.faces
        force = np.einsum("nji,nj->ni", fc.R, dt) * (fc.area / 3.0)[:, None]
        fu = fc.dofs.sign[None, :] * np.tile(force, (1, 6)) * fc.dofs.u_free
        out += np.bincount(fc.dofs.u.ravel(), weights=fu.ravel(), minlength=len(out))
        self.bubbles.forces(dt, out)

    def add(self, J: Any, dg: np.ndarray, dt: np.ndarray) -> None:
        """The faces' blocks for the law derivatives dg = d r/d g_loc, dt = d r/d t (nf, 3, 3): forces on the
        displacement rows, d force/d t = sign A/3 R^T, and the rows' dr/du = dr/dg_loc R (1/3) sign and dr/dt;
        then those through the bubbles."""
        fc, d = self.faces, self.faces.dofs
        n = fc.nf
        if n == 0:
            return      # (petsc4py's setValuesRCV divides by the number of rows)
        sign = d.sign.reshape(6, 3)[:, 0]
        blk = (sign[None, :, None, None] * (fc.area / 3.0)[:, None, None, None]
               * np.transpose(fc.R, (0, 2, 1))[:, None, :, :]).reshape(n, 18, 3)
        J.setValuesRCV(d.g_u, d.g_lm, (blk * d.u_free[:, :, None]).reshape(n, 54), addv=ADD)
        drdg = np.einsum("nij,njk->nik", dg, fc.R) / 3.0
        blk = (sign[None, None, :, None] * drdg[:, :, None, :]).reshape(n, 3, 18) * d.u_free[:, None, :]
        J.setValuesRCV(d.g_lm, d.g_u, blk.reshape(n, 54), addv=ADD)
        J.setValuesRCV(d.g_lm, d.g_lm, dt.reshape(n, 9), addv=ADD)
        per_area = dg / np.maximum(fc.area, 1e-300)[:, None, None]       # d r / d(A g)
        for kind, rows, cols, vals in self.bubbles.jacobian_blocks(per_area):
            if len(rows) == 0:
                continue
            if kind == "fu":
                rows, cols = d.g_lm[rows], self.bubbles.g_dofs(cols)
            elif kind == "ff":
                rows, cols = d.g_lm[rows], d.g_lm[cols]
            else:
                rows, cols = self.bubbles.g_dofs(rows), d.g_lm[cols]
            J.setValuesRCV(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType), vals.reshape(len(vals), -1),
                           addv=ADD)

    def pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) global index pairs of the bubbles' blocks (rows of any rank)."""
        (f, dofs), (fa, fb) = self.bubbles.pattern()
        g_lm, gd = self.faces.dofs.g_lm, self.bubbles.g_dofs(dofs)
        rows = [np.repeat(g_lm[f], 12, axis=1), np.repeat(gd, 3, axis=1), np.repeat(g_lm[fa], 3, axis=1)]
        cols = [np.tile(gd, (1, 3)), np.tile(g_lm[f], (1, 12)), np.tile(g_lm[fb], (1, 3))]
        return (np.concatenate([r.ravel() for r in rows]).astype(np.int64),
                np.concatenate([c.ravel() for c in cols]).astype(np.int64))
