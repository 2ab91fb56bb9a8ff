"""The discrete problem: F(u) = K u - f(t) (+ fault terms), Dirichlet rows, and the SNES that solves it."""

from __future__ import annotations

import time

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..physics import elasticity as el
from ..physics.contact import SLIP
from .setup import apply_solver_defaults, rigid_body_modes

# reuse mode: a Newton step that cut the residual by at least this factor lets the next one keep the factorisation
REUSE_CONTRACTION = 0.1
# a Newton solve whose last STALL_ITS iterations cut the residual by less than STALL_FACTOR in all has stalled
# (a slip direction at its regularisation kink, the line search taking tiny steps). Within STALL_ACCEPT times
# the absolute tolerance it counts as converged (CONVERGED_ITS): Newton sits on the floor of its nonsmooth
# residual; above that it stops as if it had reached -snes_max_it, and the active-set loop changes fewer faces
STALL_ITS = 5
STALL_FACTOR = 0.5
STALL_ACCEPT = 10.0
# within STALL_ACCEPT times the absolute tolerance a single iteration that cuts |F| by less than FLAT_FACTOR
# is already a stall: accepted at once instead of after STALL_ITS iterations (each may refactor)
FLAT_FACTOR = 0.9


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
        self.K = self._build_operator()
        self.bc_rows = self._constrained_rows()
        self.lifts = self._prescribed_displacements()
        self.K.zeroRowsColumns(self.bc_rows, diag=1.0)
        self.assembly_wall = time.perf_counter() - t0
        self.log_assembly.end()
        self.nullspace = rigid_body_modes(mesh, dofmap, self.dm)
        self.K.setNearNullSpace(self.nullspace)
        self._after_operator()

        self.u = self.dm.createGlobalVec()
        self.u.setName("displacement")
        self.u_ref = self.u.duplicate()
        self.f = self.u.duplicate()
        self.F = self.u.duplicate()
        self.static_local = np.zeros(dofmap.n_local)
        self.sigma0 = None
        # boundary loads per surface, scaled by the surface's history at each time
        self.surface_loads = []
        for i, b in enumerate(boundaries):
            if b.kind in ("traction", "displacement") and any(b.traction):
                loc = np.zeros(dofmap.n_local)
                tr = [bb.traction if j == i else (0.0, 0.0, 0.0) for j, bb in enumerate(boundaries)]
                assembler.traction_load(tr, loc)
                self.surface_loads.append((b, loc))

    def _build_operator(self):
        K = self.dm.createMatrix()
        K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.asm.add_stiffness(K)
        K.assemble()
        return K

    def _after_operator(self):
        pass

    # -- constraints ---------------------------------------------------------------------------
    def _constrained_local(self):
        """Boolean mask of the local dofs fixed by Dirichlet conditions."""
        mask = self.mesh.vert_data[:, 0]
        loc = np.zeros(self.dofmap.n_local, dtype=bool)
        for side in (0, 1):
            sel = self.dofmap.vert_sides > side
            dofs = self.dofmap.vertex_dofs(side)[sel]
            bits = (mask[sel, None] >> np.arange(3)) & 1
            loc[dofs[bits == 1]] = True
        return loc

    def _constrained_rows(self):
        loc = self._constrained_local().astype(float)
        g = self._to_global(loc, PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        rows = (np.nonzero(g.getArray() > 0.5)[0] + start).astype(PETSc.IntType)
        g.destroy()
        self.bc_local_owned = rows - start
        return rows

    def _prescribed_displacements(self):
        """For each displacement boundary: (boundary, g on its constrained dofs, lift = -K g) as global Vecs."""
        out = []
        which = self.mesh.vert_displacement_bc
        mask = self.mesh.vert_data[:, 0]
        for i, b in enumerate(self.boundaries):
            if b.kind != "displacement" or not any(b.displacement):
                continue
            loc = np.zeros(self.dofmap.n_local)
            for side in (0, 1):
                sel = (self.dofmap.vert_sides > side) & (which == i)
                dofs = self.dofmap.vertex_dofs(side)[sel]
                bits = ((mask[sel, None] >> np.arange(3)) & 1) * ((b.components >> np.arange(3)) & 1)
                vals = np.broadcast_to(np.asarray(b.displacement), dofs.shape)
                loc[dofs[bits == 1]] = vals[bits == 1]
            g = self._to_global(loc, PETSc.InsertMode.INSERT_VALUES)
            lift = g.duplicate()
            self.K.mult(g, lift)
            lift.scale(-1.0)
            out.append((b, g, lift))
        return out

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
        iv = getattr(self, "_dp_interval", None)
        if iv is not None and iv[0] < t < iv[2]:
            theta = (t - iv[0]) / (iv[2] - iv[0])
            return (1.0 - theta) * iv[1] + theta * iv[3]
        return self.drawdown.cell_values(t, self.mesh.cell_material, self.asm.centroids)

    def set_load(self, t):
        loc = self.static_local.copy()
        for b, fl in self.surface_loads:
            loc += b.scale(t) * fl
        if self.drawdown.active:
            self.asm.pore_pressure_load(self.cell_dp(t), loc)
        self._to_global(loc, out=self.f)
        for b, g, lift in self.lifts:
            self.f.axpy(b.scale(t), lift)
        arr = self.f.getArray()
        arr[self.bc_local_owned] = 0.0
        for b, g, lift in self.lifts:
            arr[self.bc_local_owned] += b.scale(t) * g.getArray()[self.bc_local_owned]

    def geostatic_prestress(self, snes):
        """Initial (geostatic) stress state, assumed in equilibrium with zero displacement.

        The vertical stress comes from an elastic gravity solve (faults glued), which gives the overburden
        in flat layers and the arching around stiff bodies; the horizontal stresses follow the K0 rule on
        effective stresses, sigma'_h = K0 sigma'_v, with hydrostatic pore pressure below the water table
        (K0 = -pfault_geostatic_k0, default nu/(1-nu) of each material); no initial shear. The state loads
        nothing: displacements are those caused by the drawdown, and stresses and fault tractions are the
        initial ones plus the changes.
        """
        s = self.settings
        grav = np.zeros(self.dofmap.n_local)
        self.asm.gravity_load(s.gravity, grav)
        self._to_global(grav, out=self.f)
        self.f.getArray()[self.bc_local_owned] = 0.0
        ug = self.u.duplicate()
        self._solve_gravity(snes, ug)
        sig = self.asm.effective_stress(self.local_array(ug))
        ug.destroy()
        z = self.asm.centroids[:, 2]
        p0 = s.water_density * s.gravity * np.maximum(s.water_table - z, 0.0)
        alpha = self.asm.alpha
        nu = self.asm.lam / (2 * (self.asm.lam + self.asm.mu))
        k0 = np.full(len(z), s.k0) if s.k0 >= 0 else nu / (1 - nu)
        sv = sig[:, 2, 2]
        sh = k0 * (sv + alpha * p0) - alpha * p0
        sigma0 = np.zeros_like(sig)
        sigma0[:, 0, 0] = sigma0[:, 1, 1] = sh
        sigma0[:, 2, 2] = sv
        self.sigma0 = sigma0
        self.u.set(0.0)
        return sigma0

    def _solve_gravity(self, snes, ug):
        ksp = snes.getKSP()
        ksp.setOperators(self.K, self.K)
        ksp.solve(self.f, ug)

    # -- SNES callbacks --------------------------------------------------------------------------
    def residual(self, snes, x, F):
        self.log_residual.begin()
        self.K.mult(x, F)
        F.axpy(-1.0, self.f)
        self.log_residual.end()

    def jacobian(self, snes, x, J, P):
        # linear skeleton: K is assembled once; an unchanged operator keeps its factorisation
        pass

    def solve_step(self, snes, t):
        self.set_load(t)
        t0 = time.perf_counter()
        snes.solve(None, self.u)
        reason = snes.getConvergedReason()
        return {"time_s": float(t), "newton_its": int(snes.getIterationNumber()),
                "ksp_its": int(snes.getLinearSolveIterations()), "wall_s": time.perf_counter() - t0,
                "converged": bool(reason > 0), "reason": int(reason)}

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
    def cell_total_stress(self, u_local, dp):
        """Total stress per cell: initial + C:eps(u) - alpha dp I (dp per cell, Pa)."""
        sig = self.asm.effective_stress(u_local)
        if self.sigma0 is not None:
            sig = sig + self.sigma0
        return sig - (self.asm.alpha * dp)[:, None, None] * np.eye(3)

    def destroy(self):
        for obj in (self.K, self.u, self.u_ref, self.f, self.F, self.nullspace):
            obj.destroy()
        for _, g, lift in self.lifts:
            g.destroy()
            lift.destroy()


class FaultProblem(ElasticProblem):
    """Elasticity with fault interfaces: F(x) = K u - f + interface terms; Newton on a fixed active set,
    repeated until the stick/slip/open configuration settles."""

    def __init__(self, mesh, dofmap, assembler, boundaries, drawdown, settings, fault_settings, fault_id, pairs,
                 pair_S, materials, contact_opts):
        self.fault_settings = fault_settings
        self._fault_args = (fault_id, pairs, pair_S, materials)
        self.contact_opts = contact_opts
        super().__init__(mesh, dofmap, assembler, boundaries, drawdown, settings)

    def _build_operator(self):
        from .fault import FaultSystem
        fault_id, pairs, pair_S, materials = self._fault_args
        K0 = self.dm.createMatrix()
        K0.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        bc_local = self._constrained_local()
        self.faults = FaultSystem(self.mesh, self.dofmap, self.fault_settings, fault_id, pairs, pair_S, materials,
                                  bc_local, self.dm.getLGMap())
        self.faults.slip_reg = self.contact_opts["slip_regularization"] * self.faults.h
        if self.contact_opts["slip_direction"] == "augmented":
            self.faults.c_slip = self.faults.kt * self.contact_opts["slip_augmentation"]
        self.asm.add_stiffness(K0)
        self.faults.insert_pattern(K0)
        K0.assemble()
        rows, cols = self.faults.stabilization_pattern()
        if self.comm.tompi4py().allreduce(len(rows)) > 0:
            K = _extend_pattern(K0, rows, cols)
            K0.destroy()
        else:
            K = K0
        return K

    @property
    def slip_direction(self):
        """The slip direction law in use: augmented (faults.c_slip set) or increment."""
        return "increment" if self.faults.c_slip is None else "augmented"

    def _after_operator(self):
        self._jacobian_key = None
        self._all_lagrange = self.comm.tompi4py().allreduce(bool(np.all(self.faults.lagrange)), op=MPI.LAND)
        self.J = self.K.duplicate(copy=True)
        self.J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.J.setNearNullSpace(self.nullspace)
        self.F_local = np.zeros(self.dofmap.n_local)

    def _lm_all(self, x_loc):
        f = self.faults
        t = np.zeros((f.nf, 3))
        if f.has_lagrange:
            t = f.tractions(x_loc)
        return f.gather_faces(t) if len(f.pairs) else None

    def residual(self, snes, x, F):
        self.log_residual.begin()
        self.K.mult(x, F)
        F.axpy(-1.0, self.f)
        x_loc = self.local_array(x)
        out = np.zeros(self.dofmap.n_local)
        self.faults.residual(x_loc, self._lm_all(x_loc), out)
        g = self._to_global(out)
        F.axpy(1.0, g)
        g.destroy()
        self.log_residual.end()

    def jacobian(self, snes, x, J, P):
        # with every face stuck or open (no slip, no penalty face) the Jacobian depends on the configuration
        # only: an unchanged configuration leaves J untouched, and the PC keeps its factorisation
        f = self.faults
        constant = self._all_lagrange and not np.any(f.state_all == SLIP)
        key = f.state_all.copy()
        if constant and self._jacobian_key is not None and np.array_equal(key, self._jacobian_key):
            return
        self._jacobian_key = key if constant else None
        self.K.copy(self.J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        x_loc = self.local_array(x)
        self.faults.add_jacobian(x_loc, self._lm_all(x_loc), self.J)
        self.J.assemble()
        if self._reuse:
            self._reused = not self._refactor_needed(snes, key)
            if not self._reused:
                self.J.copy(self.P, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
                self._factor_key = key
                self._force_refactor = False
                self.n_factorizations += 1
            return
        self.n_factorizations += 1
        if self.P is not self.J:
            self.J.copy(self.P, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            self.faults.add_augmentation(self.P)
            self.P.assemble()

    def _refactor_needed(self, snes, key):
        """Whether this Newton iteration refactors (reuse mode): on a new stick/slip/open configuration, when
        asked to (a GMRES solve on the reused factorisation failed), or when the last Newton step cut the
        residual less than tenfold (the Jacobian is still moving); otherwise the last factorisation
        preconditions GMRES on the exact Jacobian."""
        if self._force_refactor or self._factor_key is None or not np.array_equal(key, self._factor_key):
            return True
        k = snes.getIterationNumber() if snes is not None else 0
        if k == 0:
            return False
        hist = self._fnorms          # this solve's residual norms, recorded by the convergence test
        if len(hist) <= k:
            return True
        return not hist[k] <= REUSE_CONTRACTION * hist[k - 1]

    def _converged(self, snes, its, norms):
        """PETSc's default convergence test (SNESConvergedDefault: atol, rtol, stol, divergence tolerance,
        function-count limit) plus a stall test: STALL_ITS iterations that cut |F| by less than STALL_FACTOR
        end the solve, with CONVERGED_ITS within STALL_ACCEPT atol, else with DIVERGED_MAX_IT; within
        STALL_ACCEPT atol one iteration that cuts |F| by less than FLAT_FACTOR already ends it (CONVERGED_ITS)."""
        xnorm, ynorm, fnorm = norms
        R = PETSc.SNES.ConvergedReason
        rtol, atol, stol, _ = snes.getTolerances()
        if its == 0:
            self._fnorms = []
        self._fnorms.append(fnorm)
        f0 = self._fnorms[0]
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if fnorm < atol:
            return R.CONVERGED_FNORM_ABS
        nmax = snes.getMaxFunctionEvaluations()
        if nmax >= 0 and snes.getFunctionEvaluations() >= nmax:
            return R.DIVERGED_FUNCTION_COUNT
        if its:
            if fnorm <= rtol * f0:
                return R.CONVERGED_FNORM_RELATIVE
            if ynorm < stol * xnorm:
                return R.CONVERGED_SNORM_RELATIVE
            if self._divtol > 0 and fnorm > self._divtol * f0:
                return R.DIVERGED_DTOL
            flat = fnorm <= STALL_ACCEPT * atol and fnorm > FLAT_FACTOR * self._fnorms[its - 1]
            if flat or (its >= STALL_ITS and fnorm > STALL_FACTOR * self._fnorms[its - STALL_ITS]):
                self.n_stalls += 1
                return R.CONVERGED_ITS if fnorm <= STALL_ACCEPT * atol else R.DIVERGED_MAX_IT
        return R.CONVERGED_ITERATING

    def _snes_solve(self, snes):
        """snes.solve from self.u; a linear solve that fails on a reused factorisation is retried with a
        fresh one (the Newton iterations of both attempts count)."""
        its = kits = 0
        hist = []
        while True:
            snes.setConvergenceHistory(reset=True)
            snes.solve(None, self.u)
            its += snes.getIterationNumber()
            kits += snes.getLinearSolveIterations()
            hist += [float(v) for v in snes.getConvergenceHistory()[0][:snes.getIterationNumber() + 1]]
            reason = snes.getConvergedReason()
            if not (self._reuse and reason == PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE and self._reused):
                # (a linear solve that fails on a fresh factorisation is a genuine failure)
                return reason, its, kits, hist
            self._force_refactor = True
            self.n_reuse_failures += 1

    def create_snes(self):
        reuse = bool(self.contact_opts["reuse_factorization"])
        apply_solver_defaults(linear=False, reuse_factorization=reuse)
        snes = PETSc.SNES().create(comm=self.comm)
        snes.setDM(self.dm)
        snes.getKSP().setDMActive(False)
        snes.setFunction(self.residual, self.F)
        self.P = self.J
        snes.setJacobian(self.jacobian, self.J, self.J)
        snes.setFromOptions()
        snes.setConvergenceHistory()
        self._divtol = PETSc.Options().getReal("snes_divergence_tolerance", 1e4)
        self._fnorms = []
        self.n_stalls = 0
        snes.setConvergenceTest(self._converged)
        ksp = snes.getKSP()
        self._reuse = (reuse and ksp.getPC().getType() in (PETSc.PC.Type.LU, PETSc.PC.Type.CHOLESKY)
                       and ksp.getType() != PETSc.KSP.Type.PREONLY)
        self._factor_key = None
        self._force_refactor = False
        self._reused = False        # the last Newton iteration kept the factorisation (reuse mode)
        self._atol0 = snes.getTolerances()[1]
        self._last = None           # (u at the start of the last converged step, its start time, its end time)
        self._t_state = 0.0         # time of the state in self.u
        self.n_factorizations = 0
        self.n_reuse_failures = 0
        if self._reuse:
            # the factorised matrix is a separate copy, refreshed only when _refactor_needed says so
            self.P = self.J.duplicate(copy=True)
            snes.setJacobian(self.jacobian, self.J, self.P)
        elif self._configure_fieldsplit(snes.getKSP().getPC()):
            # Schur-complement fieldsplit preconditions with the augmented matrix (nonsingular displacement block)
            self.P = self.J.duplicate(copy=True)
            self.P.setNearNullSpace(self.nullspace)
            snes.setJacobian(self.jacobian, self.J, self.P)
        snes.setUp()
        self.jacobian(snes, self.u, self.J, self.P)
        ksp = snes.getKSP()
        ksp.setOperators(self.J, self.P)
        ksp.setUp()
        return snes

    def face_pore_pressure(self, t):
        """alpha p at the owned fault faces (Pa): the hydrostatic pressure below the water table at the face
        centroid when the scene starts from the geostatic state, plus the change at time t (minus cell).

        In a geostatic scene p is the absolute pressure, and it is clamped at zero unless
        ``-pfault_contact_suction``: a fault face above the lowered water table is dry. Without the geostatic
        state p is only the change from an unknown initial pressure, and it is used as it is."""
        f = self.faults
        if not self.contact_opts["effective_stress"] or not f.nf:
            return np.zeros(f.nf)
        s = self.settings
        p = np.zeros(f.nf)
        if s.geostatic:
            z = self.mesh.coords[f.verts][:, :, 2].mean(axis=1)
            p += s.water_density * s.gravity * np.maximum(s.water_table - z, 0.0)
        if self.drawdown.active and t > 0:
            p += self.cell_dp(t)[f.cell]
        if s.geostatic and not self.contact_opts["suction"]:
            p = np.maximum(p, 0.0)
        return self.asm.alpha[f.cell] * p

    def set_load(self, t):
        super().set_load(t)
        self.faults.set_pore_pressure(self.face_pore_pressure(t))

    def geostatic_prestress(self, snes):
        self.faults.set_pore_pressure(self.face_pore_pressure(0.0))
        sigma0 = super().geostatic_prestress(snes)
        # the faults carry the initial stress: their tractions start from it and only the change loads
        f = self.faults
        f.t0 = f.initial_tractions(sigma0)
        loc = self.local_array(self.u)
        lag = np.nonzero(f.lagrange)[0]
        loc[f.lm_dofs[lag]] = f.t0[lag]
        self._to_global(loc, PETSc.InsertMode.INSERT_VALUES, out=self.u)
        f.begin_step(loc)
        return sigma0

    def _solve_gravity(self, snes, ug):
        """Elastic gravity state with every fault face glued (stick, zero previous jump)."""
        self.faults.begin_step(np.zeros(self.dofmap.n_local))
        saved = self.faults.state.copy()
        self.faults.state[:] = 0
        self.faults._sync_state()
        snes.solve(None, ug)
        self.faults.state = saved
        self.faults._sync_state()

    def _configure_fieldsplit(self, pc):
        """Named splits for PCFIELDSPLIT (options -fieldsplit_displacement_*, -fieldsplit_lagrange_multiplier_fault_*)
        with the rigid-body modes of the displacement block as its near-null space (for GAMG)."""
        if pc.getType() != PETSc.PC.Type.FIELDSPLIT or not self.faults.has_lagrange:
            return False
        from ..fields import DISPLACEMENT, LAGRANGE
        loc = np.zeros(self.dofmap.n_local)
        lag = np.nonzero(self.faults.lagrange)[0]
        loc[self.faults.lm_dofs[lag].ravel()] = 1.0
        g = self._to_global(loc, PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        mark = g.getArray() > 0.5
        g.destroy()
        idx = np.arange(len(mark), dtype=PETSc.IntType) + start
        self.is_u = PETSc.IS().createGeneral(idx[~mark], comm=self.comm)
        self.is_lm = PETSc.IS().createGeneral(idx[mark], comm=self.comm)
        self.is_u.setBlockSize(1)
        vecs = []
        for v in self.nullspace.getVecs():
            sub = v.getSubVector(self.is_u)
            w = sub.copy()
            v.restoreSubVector(self.is_u, sub)
            vecs.append(w)
        for i, v in enumerate(vecs):          # re-orthonormalise on the subspace
            for w in vecs[:i]:
                v.axpy(-v.dot(w), w)
            v.normalize()
        self.u_nullspace = PETSc.NullSpace().create(vectors=vecs, comm=self.comm)
        for v in vecs:
            v.destroy()
        self.is_u.compose("nearnullspace", self.u_nullspace)
        pc.setFieldSplitIS((DISPLACEMENT, self.is_u), (LAGRANGE, self.is_lm))
        return True

    def solve_interval(self, snes, t_prev, t, max_cuts=0):
        """Advance from t_prev to t. A step that does not converge is retried from the state at t_prev: with
        the augmented slip direction, first in one step with the increment direction, which then stays for
        the rest of the run (same solution, no traction steering: it settles where the augmented direction
        chatters, e.g. on a fault that starts from zero strength without geostatic stress); then as 2, 4, ...
        equal sub-steps (up to max_cuts halvings). A flow model's pore pressure is interpolated linearly in
        time within the interval (it has already been advanced to t)."""
        u0 = self.u.duplicate()
        self.u.copy(u0)
        state0 = self.faults.state.copy()
        last0 = None if self._last is None else (self._last[0].copy(), self._last[1], self._last[2])
        t_state0 = self._t_state
        flow = hasattr(self.drawdown, "advance_to") and self.drawdown.active
        dp0 = self.cell_dp(t_prev) if (flow and max_cuts > 0) else None       # before the flow moves on to t
        monitor = self.contact_opts["monitor"]

        def restart():
            u0.copy(self.u)
            self.faults.state = state0.copy()
            self.faults._sync_state()
            if self._last is not None:
                self._last[0].destroy()
            self._last = None if last0 is None else (last0[0].copy(), last0[1], last0[2])
            self._t_state = t_state0

        rec = self.solve_step(snes, t)
        tried = [rec]
        fallback = False
        if not rec["converged"] and self.faults.c_slip is not None:
            restart()
            if monitor:
                PETSc.Sys.Print(f"  step not converged ({rec['reason']}): retrying with the increment slip direction")
            self.faults.c_slip = None
            rec = self.solve_step(snes, t)
            tried.append(rec)
            fallback = True
        cuts = 0
        while not rec["converged"] and cuts < max_cuts:
            cuts += 1
            n = 2 ** cuts
            restart()
            if flow:
                self._dp_interval = (t_prev, dp0, t, self.cell_dp(t))
            if monitor:
                PETSc.Sys.Print(f"  step not converged ({rec['reason']}): retrying as {n} sub-steps")
            for k in range(1, n + 1):
                rec = self.solve_step(snes, t_prev + (t - t_prev) * k / n)
                tried.append(rec)
                if not rec["converged"]:
                    break
            self._dp_interval = None
        u0.destroy()
        if last0 is not None:
            last0[0].destroy()
        if len(tried) > 1:
            rec = dict(rec)
            for key in ("newton_its", "ksp_its", "wall_s", "active_set_its", "factorizations", "reuse_failures",
                        "newton_stalls", "chatter_releases"):
                rec[key] = sum(r.get(key, 0) for r in tried)
            rec["time_s"] = float(t)
            rec["substeps"] = 2 ** cuts
            rec["residual_history"] = [h for r in tried for h in r["residual_history"]]
        if fallback:
            rec["slip_direction_fallback"] = True
        return rec

    def solve_step(self, snes, t):
        """Newton solves until the active set settles; returns the step record."""
        import time as _time
        o = self.contact_opts
        self.set_load(t)
        x_loc = self.local_array(self.u)
        t0 = _time.perf_counter()
        u_start = self.u.duplicate()
        self.u.copy(u_start)
        t_start = self._t_state
        carry, du = self._predictor(t, x_loc)
        self.faults.begin_step(x_loc, carry)
        if du is not None:
            self.u.axpy(1.0, du)
            du.destroy()
        self._step_tolerance(snes)
        newton = ksp = 0
        history = []
        settled = False
        converged = True
        reason = 0
        total_area = self.comm.tompi4py().allreduce(float(self.faults.area.sum()))
        x_conv = self.u.duplicate()
        self.u.copy(x_conv)
        self.faults.save_state()
        fraction = 1.0
        last_changes = 0
        nfact0, nfail0, nstall0 = self.n_factorizations, self.n_reuse_failures, self.n_stalls
        it = releases = 0
        last_reason = 0
        limit = o["max_active_set_its"]
        while it < limit:
            it += 1
            nstall_round = self.n_stalls
            reason, its, kits, hist = self._snes_solve(snes)
            newton += its
            ksp += kits
            history.append(hist)
            if reason > 0:
                self.u.copy(x_conv)
                self.faults.save_state()
                # after a bounded update the share of faces changed grows back gradually: going back to all
                # of them at once re-proposes the change that failed (a front of opening faces with the
                # stick->slip ones next to it)
                growth = o["bounded_growth"]
                fraction = min(1.0, fraction * growth) if growth >= 1.0 else 1.0
            elif reason in (-5, -6):            # DIVERGED_MAX_IT, DIVERGED_LINE_SEARCH
                # Newton could not solve this configuration: go back to the last solved one and change
                # fewer faces, those that ask for it most strongly (bounded configuration update); if even a
                # single face's change cannot be solved, that change is banned for the rest of the step
                single = last_changes <= 1
                x_conv.copy(self.u)
                self.faults.restore_state()
                if single:
                    self.faults.ban_last_change()
                fraction *= 0.25
            else:
                converged = False
                break
            x_loc = self.local_array(self.u)
            changed = self.faults.update_active_set(x_loc, o["traction_tol"], o["opening_tol"], o["slip_tol"],
                                                    fraction)
            last_changes = int(self.faults.last_transitions.sum() - np.trace(self.faults.last_transitions))
            if o["monitor"]:
                tr = self.faults.last_transitions
                status = "converged" if reason > 0 else "failed"
                status += ", stalled" if self.n_stalls > nstall_round else ""
                PETSc.Sys.Print(f"  active set {it:2d}: newton {its:2d} ({status}, "
                                f"|F| {history[-1][-1]:.3e})  stick->slip {tr[0, 1]}  slip->stick {tr[1, 0]}  "
                                f"->open {tr[0, 2] + tr[1, 2]}  open->stick {tr[2, 0]}"
                                + ("" if fraction == 1.0 else f"  (bounded update: {fraction:g})"))
            if reason > 0 and changed <= o["active_set_tol"] * total_area:
                if releases < o["chatter_releases"]:
                    # faces the anti-chatter rule holds in a state the contact conditions reject beyond
                    # chatter_tol are released and the updates go on (a fresh budget of rounds)
                    n = self.faults.release_frozen(x_loc, o["traction_tol"], o["opening_tol"], o["slip_tol"],
                                                   o["chatter_tol"])
                    if n:
                        releases += 1
                        limit = it + o["max_active_set_its"]
                        if o["monitor"]:
                            PETSc.Sys.Print(f"  released {n} faces held by the anti-chatter rule in a state the "
                                            f"contact conditions reject ({releases} of "
                                            f"{o['chatter_releases']})")
                        continue
                settled = True
                break
            if reason <= 0 and changed == 0.0:
                # back at the last solved configuration (if any), and every change its faces ask for is
                # banned: it stands as the step's solution if the banned faces' violations are within
                # chatter_tol
                if last_reason > 0:
                    reason = last_reason
                    settled = True
                else:
                    converged = False
                break
            if reason > 0:
                last_reason = reason
        x_conv.destroy()
        x_loc = self.local_array(self.u)
        counts = self.faults.counts_by_state(x_loc)
        rec = {"time_s": float(t), "newton_its": int(newton), "ksp_its": int(ksp),
               "wall_s": _time.perf_counter() - t0, "active_set_its": it, "active_set_settled": bool(settled),
               "factorizations": int(self.n_factorizations - nfact0),
               "reuse_failures": int(self.n_reuse_failures - nfail0),
               "newton_stalls": int(self.n_stalls - nstall0), "chatter_releases": int(releases),
               "converged": bool(converged and settled), "reason": int(reason), "residual_history": history}
        rec.update(counts)
        rec["frozen_faces"] = self.faults.frozen_count()
        nbad, worst = self.faults.frozen_violations(x_loc, o["traction_tol"], o["opening_tol"], o["slip_tol"])
        rec["frozen_violating"], rec["frozen_max_violation"] = nbad, worst
        if converged and settled and nbad > 0 and worst > o["chatter_tol"]:
            # faces held in place by the anti-chatter rule break the contact conditions: not a solution
            rec["converged"] = False
            rec["reason"] = (f"{nbad} faces kept by the anti-chatter rule violate the contact conditions by up to "
                             f"{worst:.3g} of the median normal traction (-pfault_contact_chatter_tol {o['chatter_tol']:g})")
        if converged and not settled:
            rec["reason"] = "active set did not settle"
        if self._last is not None:
            self._last[0].destroy()
        self._last = (u_start, t_start, float(t)) if rec["converged"] else None
        if not rec["converged"]:
            u_start.destroy()
        self._t_state = float(t)
        return rec

    def _step_tolerance(self, snes):
        """Newton solves of this step stop once |F| <= step_rtol |F(start of the step)| (or at the user's
        -snes_atol / -snes_rtol, whichever comes first): the rounds after an active-set change are not held
        to a tolerance relative to their own, much smaller, initial residual only."""
        rtol_step = self.contact_opts["step_rtol"]
        if rtol_step <= 0:
            return
        self.residual(snes, self.u, self.F)
        f0 = self.F.norm()
        rtol, _, stol, max_it = snes.getTolerances()
        snes.setTolerances(rtol=rtol, atol=max(self._atol0, rtol_step * f0), stol=stol, max_it=max_it)

    def _predictor(self, t, x_loc):
        """First guess of a step from the last converged one (u_n + (t - t_n)/(t_n - t_n-1) (u_n - u_n-1),
        displacements and multipliers) and the faces that keep slipping into it: those whose slip increment
        in the last step exceeded the regularisation (augmented slip direction only). (None, None) without a
        previous step."""
        if (not self.contact_opts["predictor"] or self._last is None
                or self.faults.c_slip is None):
            # not with the increment slip law: its direction is singular at a zero increment, which Newton
            # must reach from an overshooting prediction when the loading stops
            return None, None
        u_prev, t_a, t_b = self._last
        if not (t_b > t_a and t > t_b and t_b == self._t_state):
            return None, None
        du = self.u.duplicate()
        self.u.copy(du)
        du.axpy(-1.0, u_prev)
        f = self.faults
        _, g_now = f.jumps(x_loc)
        _, g_before = f.jumps(self.local_array(u_prev))
        slid = np.linalg.norm(g_now[:, 1:] - g_before[:, 1:], axis=1)
        carry = (f.state == SLIP) & f.lagrange & (slid > np.maximum(f.slip_reg, f.slide_tol))
        du.scale((t - t_b) / (t_b - t_a))
        return carry, du

    def destroy(self):
        super().destroy()
        if getattr(self, "P", None) is not None and self.P is not self.J:
            self.P.destroy()
        self.J.destroy()
        for name in ("is_u", "is_lm", "u_nullspace"):
            if hasattr(self, name):
                getattr(self, name).destroy()
        if getattr(self, "_last", None) is not None:
            self._last[0].destroy()
            self._last = None


def _extend_pattern(K0, rows, cols):
    """A new AIJ matrix with K0's values and pattern plus explicit zeros at (rows, cols) (owned rows)."""
    rstart, rend = K0.getOwnershipRange()
    indptr, indices, values = K0.getValuesCSR()
    nrows = rend - rstart
    r_old = np.repeat(np.arange(nrows), np.diff(indptr))
    r_all = np.concatenate([r_old, np.asarray(rows) - rstart])
    c_all = np.concatenate([indices, np.asarray(cols)])
    v_all = np.concatenate([values, np.zeros(len(rows))])
    if len(rows) and (np.min(r_all) < 0 or np.max(r_all) >= nrows):
        raise RuntimeError("stabilisation rows must be owned")
    ncols = K0.getSize()[1]
    key = r_all.astype(np.int64) * ncols + c_all.astype(np.int64)
    uniq, inv = np.unique(key, return_inverse=True)
    vals = np.zeros(len(uniq))
    np.add.at(vals, inv, v_all)
    r_u = (uniq // ncols).astype(np.int64)
    c_u = (uniq % ncols).astype(PETSc.IntType)
    ptr = np.concatenate([[0], np.cumsum(np.bincount(r_u, minlength=nrows))]).astype(PETSc.IntType)
    K = PETSc.Mat().createAIJ(size=K0.getSizes(), csr=(ptr, c_u, vals), comm=K0.getComm())
    K.setLGMap(*K0.getLGMap())
    K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    K.assemble()
    return K
