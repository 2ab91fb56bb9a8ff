"""The equations: F(x) = K u - f(t) + the terms' residuals, with Dirichlet rows, and their Jacobian.

The elastic skeleton is given a list of terms (pfault.solver.terms: a fault interface, pfault.faults.term); with
none F is linear and K its Jacobian; the terms add their residual rows and Jacobian blocks, reading their state
(a fault face's stick/slip/open) from each iterate, given their histories. How the equations are solved (SNES
and KSP set-up, predictor, factor reuse, step cutting) is ``pfault.solver.policy``'s.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..physics import geostatic as gs
from .loads import Loads
from .operator import build_operator
from .setup import rigid_body_modes


def constrained_local(mesh: Any, dofmap: Any) -> np.ndarray:
    """Boolean mask of the local dofs fixed by Dirichlet conditions."""
    mask = mesh.vert_data[:, 0]
    loc = np.zeros(dofmap.n_local, dtype=bool)
    for side in range(dofmap.max_sides):
        sel = dofmap.vert_sides > side
        dofs = dofmap.vertex_dofs(side)[sel]
        bits = (mask[sel, None] >> np.arange(3)) & 1
        loc[dofs[bits == 1]] = True
    return loc


class Equations:
    """Linear elastic skeleton loaded by the pore-pressure change of ``source``, gravity/prestress and
    tractions (``loads``, a pfault.solver.loads.Loads), with the ``terms`` (pfault.solver.terms). ``J`` holds
    the Jacobian last assembled. The terms' histories are arguments (``histories``: one per term, in order)."""

    def __init__(self, mesh: Any, dofmap: Any, assembler: Any, boundaries: list, source: Any, settings: Any,
                 terms: tuple = ()) -> None:
        self.mesh, self.dofmap, self.asm = mesh, dofmap, assembler
        self.dm = mesh.dm
        self.comm = self.dm.getComm()
        self.settings, self.terms = settings, tuple(terms)
        self._log_residual = PETSc.Log.Event("pfaultResidual")
        self._log_jacobian = PETSc.Log.Event("pfaultJacobian")
        log_assembly = PETSc.Log.Event("pfaultAssembleK")
        self.comm.tompi4py().Barrier()  # assembly_wall times the assembly, not the ranks' arrival (as DOLFINx's)
        log_assembly.begin()
        t0 = time.perf_counter()
        self.K = build_operator(self.dm, self.asm, self.dofmap, self.terms)
        self.bc_rows = self._constrained_rows()
        # the lifts of prescribed displacements take K before its constrained rows and columns are zeroed
        self.loads = Loads(self, boundaries, source, settings)
        self.K.zeroRowsColumns(self.bc_rows, diag=1.0)
        self.assembly_wall = time.perf_counter() - t0
        log_assembly.end()
        self.nullspace = rigid_body_modes(mesh, dofmap, self.dm)
        self.K.setNearNullSpace(self.nullspace)
        self.J = self.K
        if not self.linear:
            self.J = self.K.duplicate(copy=True)
            self.J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
            self.J.setNearNullSpace(self.nullspace)
        self.n_jacobians = 0            # Jacobians of the terms assembled (a configuration seen before is kept)
        self._jacobian_key: np.ndarray | None = None    # the terms' configuration of J while it depends on nothing else
        self.jacobian_configuration: np.ndarray | None = None  # the terms' configuration J was last assembled in
        # J last assembled differs from any other of its configuration in stiffness moduli only (Term.moduli_vary_only)
        self.moduli_vary_only = True

    @property
    def linear(self) -> bool:
        """No term: F is K u - f, and K its Jacobian."""
        return not self.terms

    # -- constraints ---------------------------------------------------------------------------
    def _constrained_rows(self) -> np.ndarray:
        loc = constrained_local(self.mesh, self.dofmap).astype(float)
        g = self.to_global(loc, PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        rows = (np.nonzero(g.getArray() > 0.5)[0] + start).astype(PETSc.IntType)
        g.destroy()
        self.bc_local_owned = rows - start
        return rows

    # -- vectors -------------------------------------------------------------------------------
    def create_vec(self) -> Any:
        return self.dm.createGlobalVec()

    def to_global(self, local_array: np.ndarray, mode: Any = PETSc.InsertMode.ADD_VALUES, out: Any = None) -> Any:
        """A local array (this rank's dofs with its ghosts) into a global vector: ``out`` or a new one; with
        ADD_VALUES the ghosts' contributions are summed (an assembled load), with INSERT_VALUES set (a state)."""
        lv = self.dm.getLocalVec()
        lv.setArray(local_array)
        g = out if out is not None else self.dm.createGlobalVec()
        if out is not None and mode == PETSc.InsertMode.ADD_VALUES:
            g.set(0.0)
        self.dm.localToGlobal(lv, g, addv=mode)
        self.dm.restoreLocalVec(lv)
        return g

    def local_array(self, gvec: Any) -> np.ndarray:
        lv = self.dm.getLocalVec()
        self.dm.globalToLocal(gvec, lv, addv=PETSc.InsertMode.INSERT_VALUES)
        a = lv.getArray().copy()
        self.dm.restoreLocalVec(lv)
        return a

    # -- the terms' histories and configurations --------------------------------------------------
    def initial_histories(self) -> tuple:
        return tuple(term.initial_history() for term in self.terms)

    def begin_step(self, x: Any, histories: tuple) -> tuple:
        """The terms' histories with the converged state x (under the loads last set: those it was solved for)
        as the start of a solve."""
        x_loc = self.local_array(x)
        return tuple(term.begin_step(x_loc, load, h)
                     for term, load, h in zip(self.terms, self.loads.term_loads, histories))

    def configuration(self, x: Any, histories: tuple, exact: bool = True) -> tuple:
        """Each term's configuration at x (``exact``: the branches the residual takes; else as reported)."""
        x_loc = self.local_array(x)
        return tuple(term.configuration(x_loc, load, h, exact)
                     for term, load, h in zip(self.terms, self.loads.term_loads, histories))

    def settle(self, x: Any, histories: tuple, t: float, errors: tuple | None = None) -> tuple[tuple, int | None]:
        """The terms' histories settled at the iterate x of a solve at time t (pfault.solver.terms: a fault's faces
        that break) and how many of their parts changed on all ranks, or None where a term's verdict is open within
        its error (``errors``: one per term, a bound on the error of what it reads at x; None: x is converged).
        Collective."""
        x_loc = self.local_array(x)
        errors = errors if errors is not None else (0.0,) * len(self.terms)
        settled = [term.settle(x_loc, load, h, t, e)
                   for term, load, h, e in zip(self.terms, self.loads.term_loads, histories, errors)]
        if any(n is None for _, n in settled):
            return histories, None
        return tuple(h for h, _ in settled), sum(n for _, n in settled)

    def settle_changes(self, dx: Any) -> tuple:
        """Each term's size of the change dx of the iterate in what its ``settle`` reads. Collective."""
        dx_loc = self.local_array(dx)
        return tuple(term.settle_change(dx_loc) for term in self.terms)

    def trial_configuration(self, histories: tuple) -> tuple:
        return tuple(term.trial_configuration(h) for term, h in zip(self.terms, histories))

    def counts(self, x: Any, histories: tuple, loads: tuple | None = None) -> dict:
        """Each term's counts of its configuration at x, as reported (a fault's faces stuck/slipping/open, a soil's
        cells compacting on the virgin line), merged; ``loads``: the terms' loads, by default those last set.
        Collective."""
        x_loc = self.local_array(x)
        out: dict = {}
        for term, load, h in zip(self.terms, self.loads.term_loads if loads is None else loads, histories):
            out.update(term.counts(term.configuration(x_loc, load, h, exact=False)))
        return out

    # -- the initial gravity state -------------------------------------------------------------
    def initial_operator(self) -> Any:
        """The operator of the elastic gravity solve: K, with the terms' blocks of the initial state (every fault
        face glued, no jump, while it forms)."""
        if self.linear:
            return self.K
        A = self.J
        self.K.copy(A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        config = tuple(term.add_initial_operator(A, self.dofmap.n_local) for term in self.terms)
        A.assemble()
        # a first step that starts in this configuration keeps this factorisation
        varies = any(term.jacobian_varies(c) for term, c in zip(self.terms, config))
        self.jacobian_configuration = _flat(config)
        self._jacobian_key = None if varies else self.jacobian_configuration
        return A

    def effective_stress(self, u_local: np.ndarray, histories: tuple, loads: tuple | None = None) -> np.ndarray:
        """Incremental effective stress per cell (nc, 3, 3), its mean over the cell: C:eps of the P1 displacements
        of ``u_local``, or the law's in the cells a term gives their stress (a material with memory), plus the
        stress the terms add (a fault's face bubbles in the cells beside it, recovered from u_local's multipliers,
        in the bubbles' moduli) under the terms' ``loads``, by default those last set."""
        sig = self.asm.effective_stress(u_local)
        loads = self.loads.term_loads if loads is None else loads
        for term, load, h in zip(self.terms, loads, histories):
            cells, stress = term.cell_stress(u_local, load, h)
            sig[cells] = stress
        for term, load, h in zip(self.terms, loads, histories):
            cells, added = term.added_stress(u_local, load, h)
            sig[cells] += added
        return sig

    def cell_total_stress(self, u_local: np.ndarray, dp: np.ndarray, sigma0: np.ndarray | None,
                          histories: tuple, loads: tuple | None = None) -> np.ndarray:
        """Total stress per cell: initial + C:eps(u) - alpha dp I (dp per cell, Pa; ``Loads.cell_dp``), with the
        terms' added stress (``effective_stress``)."""
        sig = self.effective_stress(u_local, histories, loads)
        if sigma0 is not None:
            sig = sig + sigma0
        return sig - (self.asm.alpha * dp)[:, None, None] * np.eye(3)

    # -- residual and Jacobian -----------------------------------------------------------------
    def residual(self, x: Any, F: Any, histories: tuple, config: tuple | None = None) -> None:
        """F(x) given the terms' histories; ``config``: the terms' configurations to take instead of those read
        from x (a step's elastic trial)."""
        self._log_residual.begin()
        self.K.mult(x, F)
        F.axpy(-1.0, self.loads.f)
        if self.terms:
            out = np.zeros(self.dofmap.n_local)
            x_loc = self.local_array(x)
            for k, (term, load, h) in enumerate(zip(self.terms, self.loads.term_loads, histories)):
                term.residual(x_loc, load, h, out, None if config is None else config[k])
            g = self.to_global(out)
            F.axpy(1.0, g)
            g.destroy()
        self._log_residual.end()

    def assemble_jacobian(self, x: Any, J: Any, histories: tuple, config: tuple | None = None) -> np.ndarray | None:
        """K plus the terms' blocks at x into J. While the terms' Jacobian depends on their configuration only (no
        slipping fault face) an unchanged configuration leaves J untouched. Returns the configuration of a newly
        assembled J (the terms' concatenated), None when J was kept (and when there is no term)."""
        if self.linear:
            return None      # K is assembled once
        self._log_jacobian.begin()
        x_loc = self.local_array(x)
        loads = self.loads.term_loads
        state = config if config is not None else tuple(
            term.configuration(x_loc, load, h) for term, load, h in zip(self.terms, loads, histories))
        varying = [term.jacobian_varies(c) for term, c in zip(self.terms, state)]
        varies = any(varying)
        flat, key = _flat(state), self._jacobian_key
        same = key is not None and not varies and np.array_equal(key, flat)
        if self.comm.tompi4py().allreduce(same, op=MPI.LAND):
            self._log_jacobian.end()
            return None
        self.K.copy(J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        for k, (term, load, h) in enumerate(zip(self.terms, loads, histories)):
            term.add_jacobian(x_loc, load, h, J, None if config is None else config[k])
        J.assemble()
        self.jacobian_configuration = flat
        self._jacobian_key = None if varies else flat
        self.moduli_vary_only = all(term.moduli_vary_only for term, v in zip(self.terms, varying) if v)
        self.n_jacobians += 1
        self._log_jacobian.end()
        return flat

    def destroy(self) -> None:
        self.loads.destroy()
        for obj in {id(o): o for o in (self.K, self.J, self.nullspace)}.values():
            obj.destroy()


def _flat(config: tuple) -> np.ndarray:
    """The terms' configurations as one array."""
    return np.concatenate(config) if config else np.zeros(0, np.int64)
