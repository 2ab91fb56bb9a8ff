"""Named splits for PCFIELDSPLIT: the fault multipliers and the displacement."""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

from ..fields import DISPLACEMENT, LAGRANGE


class FieldSplit:
    """Configures a PCFIELDSPLIT ``pc`` from the equations' fields and owns the index sets it gives it: the fault
    multipliers first (options -fieldsplit_lagrange_multiplier_fault_*), then the displacement
    (-fieldsplit_displacement_*), both with block size 3, the displacement with the rigid-body modes as its
    near-null space. Does nothing for another PC type.

    With -pc_fieldsplit_type schur the multipliers are eliminated first and the displacement carries the Schur
    complement K - B D^-1 C. Its "selfp" approximation with the exact 3x3 blocks of D per face
    (-fieldsplit_displacement_mat_schur_complement_ainv_type blockdiag) is the elastic stiffness plus, across
    every closed face, springs in the directions the face's state constrains: a closed face's D is its law's
    derivative times the condensed bubbles' block C K_bb^-1 C^T / A (pfault.faults.bubbles), so the springs are
    the stiffness of the bubbles of the face's two cells, of the order of the local stiffness: an augmented
    Lagrangian whose coefficient comes from the discretisation. It keeps the displacement block nonsingular
    where a fault holds a body (pfault/solver/options/iterative.opts). Where faces share a cell their blocks
    couple; only each face's own 3x3 block is used.

    A scene without faults has no multiplier field (every fault face, Lagrange or penalty, carries its traction
    as multipliers): the whole unknown is the displacement, and the PC becomes the displacement split's (its
    options, -fieldsplit_displacement_*)."""

    def __init__(self, equations: Any, pc: Any) -> None:
        self.objects: list = []
        if pc.getType() != PETSc.PC.Type.FIELDSPLIT:
            return
        if LAGRANGE not in equations.dofmap.fields:
            _displacement_only(pc)
            return
        loc = equations.dofmap.field_mask(LAGRANGE).astype(float)
        g = equations.to_global(loc, PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        mark = g.getArray() > 0.5
        g.destroy()
        idx = np.arange(len(mark), dtype=PETSc.IntType) + start
        comm = equations.comm
        is_u = PETSc.IS().createGeneral(idx[~mark], comm=comm)
        is_lm = PETSc.IS().createGeneral(idx[mark], comm=comm)
        is_u.setBlockSize(3)
        is_lm.setBlockSize(3)
        u_nullspace = _restricted_nullspace(equations.nullspace, is_u, comm)
        is_u.compose("nearnullspace", u_nullspace)
        pc.setFieldSplitIS((LAGRANGE, is_lm), (DISPLACEMENT, is_u))
        self.objects = [is_u, is_lm, u_nullspace]

    def destroy(self) -> None:
        for obj in self.objects:
            obj.destroy()
        self.objects = []


def _displacement_only(pc: Any) -> None:
    prefix = pc.getOptionsPrefix() or ""
    pc.setOptionsPrefix(prefix + "fieldsplit_displacement_")
    pc.setFromOptions()     # (the prefix stays: a later KSPSetFromOptions must not bring back -pc_type)
    # the multiplier split's options and the Schur complement's have nothing to act on here
    opts = PETSc.Options()
    for key in opts.getAll():
        if key.startswith((prefix + "fieldsplit_lagrange_multiplier_fault_", prefix + "pc_fieldsplit_",
                           prefix + "fieldsplit_displacement_ksp_", prefix + "fieldsplit_displacement_mat_schur")):
            opts.getString(key, "")


def _restricted_nullspace(nullspace: Any, is_u: Any, comm: Any) -> Any:
    """The rigid-body modes restricted to the displacement dofs, orthonormalised again on that subspace."""
    vecs = []
    for v in nullspace.getVecs():
        sub = v.getSubVector(is_u)
        vecs.append(sub.copy())
        v.restoreSubVector(is_u, sub)
    for i, v in enumerate(vecs):
        for w in vecs[:i]:
            v.axpy(-v.dot(w), w)
        v.normalize()
    ns = PETSc.NullSpace().create(vectors=vecs, comm=comm)
    for v in vecs:
        v.destroy()
    return ns
