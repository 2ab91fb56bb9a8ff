"""The discrete problem: F(u) = K u - f(t) (+ fault terms), Dirichlet rows, and the SNES that solves it."""

from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc

from ..physics import elasticity as el
from .setup import apply_solver_defaults, rigid_body_modes


class ElasticProblem:
    """Linear elastic skeleton loaded by pore-pressure change, gravity/prestress and tractions."""

    def __init__(self, mesh, dofmap, assembler, boundaries, drawdown, settings):
        self.mesh, self.dofmap, self.asm = mesh, dofmap, assembler
        self.dm = mesh.dm
        self.comm = self.dm.getComm()
        self.boundaries = boundaries
        self.drawdown = drawdown
        self.settings = settings
        self.log_assembly = PETSc.Log.Event("pfaultAssembleK")
        self.log_residual = PETSc.Log.Event("pfaultResidual")

        self.log_assembly.begin()
        t0 = time.perf_counter()
        self.K = self.dm.createMatrix()
        self.K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        assembler.add_stiffness(self.K)
        self.K.assemble()
        self.bc_rows = self._constrained_rows()
        self.K.zeroRowsColumns(self.bc_rows, diag=1.0)
        self.assembly_wall = time.perf_counter() - t0
        self.log_assembly.end()
        self.nullspace = rigid_body_modes(mesh, dofmap, self.dm)
        self.K.setNearNullSpace(self.nullspace)

        self.u = self.dm.createGlobalVec()
        self.u.setName("displacement")
        self.u_ref = self.u.duplicate()
        self.f = self.u.duplicate()
        self.F = self.u.duplicate()
        self.static_local = np.zeros(dofmap.n_local)
        self.sigma0 = None
        tractions = [b.traction for b in boundaries]
        if any(b.kind == "traction" for b in boundaries):
            assembler.traction_load(tractions, self.static_local)

    # -- constraints ---------------------------------------------------------------------------
    def _constrained_rows(self):
        mask = self.mesh.vert_data[:, 0]
        loc = np.zeros(self.dofmap.n_local)
        for side in (0, 1):
            sel = self.dofmap.vert_sides > side
            dofs = self.dofmap.vertex_dofs(side)[sel]
            bits = (mask[sel, None] >> np.arange(3)) & 1
            loc[dofs[bits == 1]] = 1.0
        g = self._to_global(loc, PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        rows = (np.nonzero(g.getArray() > 0.5)[0] + start).astype(PETSc.IntType)
        g.destroy()
        self.bc_local_owned = rows - start
        return rows

    def _to_global(self, local_array, mode=PETSc.InsertMode.ADD_VALUES, out=None):
        lv = self.dm.getLocalVec()
        lv.setArray(local_array)
        g = out if out is not None else self.dm.createGlobalVec()
        if out is not None and mode == PETSc.InsertMode.ADD_VALUES:
            g.set(0.0)
        self.dm.localToGlobal(lv, g, addv=mode)
        self.dm.restoreLocalVec(lv)
        return g

    def local_array(self, gvec):
        lv = self.dm.getLocalVec()
        self.dm.globalToLocal(gvec, lv, addv=PETSc.InsertMode.INSERT_VALUES)
        a = lv.getArray().copy()
        self.dm.restoreLocalVec(lv)
        return a

    # -- loads -----------------------------------------------------------------------------------
    def cell_dp(self, t):
        return self.drawdown.cell_values(t, self.mesh.cell_material, self.asm.centroids)

    def set_load(self, t):
        loc = self.static_local.copy()
        if self.drawdown.active:
            self.asm.pore_pressure_load(self.cell_dp(t), loc)
        self._to_global(loc, out=self.f)
        self.f.getArray()[self.bc_local_owned] = 0.0

    def geostatic_prestress(self, snes):
        """Elastic gravity solve, then horizontal effective stress set by K0; returns sigma0 per cell."""
        s = self.settings
        grav = np.zeros(self.dofmap.n_local)
        self.asm.gravity_load(s.gravity, grav)
        self._to_global(grav, out=self.f)
        self.f.getArray()[self.bc_local_owned] = 0.0
        ksp = snes.getKSP()
        ug = self.u.duplicate()
        ksp.setOperators(self.K, self.K)
        ksp.solve(self.f, ug)
        sig = self.asm.effective_stress(self.local_array(ug))
        ug.destroy()
        z = self.asm.centroids[:, 2]
        p0 = s.water_density * s.gravity * np.maximum(s.water_table - z, 0.0)
        alpha = self.asm.alpha
        nu = self.asm.lam / (2 * (self.asm.lam + self.asm.mu))
        k0 = np.full(len(z), s.k0) if s.k0 >= 0 else nu / (1 - nu)
        sv_eff = sig[:, 2, 2] + alpha * p0
        sh = k0 * sv_eff - alpha * p0
        sigma0 = sig.copy()
        sigma0[:, 0, 0] = sigma0[:, 1, 1] = sh
        sigma0[:, 0, 1] = sigma0[:, 1, 0] = 0.0
        self.sigma0 = sigma0
        self.asm.gravity_load(s.gravity, self.static_local)
        self.asm.initial_stress_load(sigma0, self.static_local)
        return sigma0

    # -- SNES callbacks --------------------------------------------------------------------------
    def residual(self, snes, x, F):
        self.log_residual.begin()
        self.K.mult(x, F)
        F.axpy(-1.0, self.f)
        self.log_residual.end()

    def jacobian(self, snes, x, J, P):
        # linear skeleton: K is assembled once; an unchanged operator keeps its factorisation
        pass

    def create_snes(self):
        apply_solver_defaults(linear=True)
        snes = PETSc.SNES().create(comm=self.comm)
        snes.setDM(self.dm)
        snes.getKSP().setDMActive(False)
        snes.setFunction(self.residual, self.F)
        snes.setJacobian(self.jacobian, self.K, self.K)
        snes.setFromOptions()
        snes.setUp()
        ksp = snes.getKSP()
        ksp.setOperators(self.K, self.K)
        ksp.setUp()
        return snes

    # -- post-processing -------------------------------------------------------------------------
    def cell_total_stress(self, u_local, t):
        sig = self.asm.effective_stress(u_local)
        if self.sigma0 is not None:
            sig = sig + self.sigma0
        dp = self.cell_dp(t) if self.drawdown.active else np.zeros(len(sig))
        return sig - (self.asm.alpha * dp)[:, None, None] * np.eye(3)

    def destroy(self):
        for obj in (self.K, self.u, self.u_ref, self.f, self.F, self.nullspace):
            obj.destroy()
