"""The materials with memory as a term of the equations: the cells of compressible layers take their effective
stress from the compression-index law (pfault.physics.soil), given each cell's memory (pfault.soils.history) and
returning the next.

The elastic operator K holds these cells with zero stiffness (their pattern only: pfault.assembly.elastic's
stiffness mask), and the term adds their internal forces V (sigma' - sigma'_0) g_a and their consistent tangent.
Removing them from K rather than correcting a reference stiffness keeps K of a scene without these materials as it
was, bit for bit, and costs one element matrix per cell and Jacobian instead of two (the tangent and the
reference it would correct); the forces come from the law's stress, not from a difference of large terms.

The cells' branch (on the swelling line or compacting on the virgin line) is the term's configuration, read from
each iterate as a fault face's state is: the semismooth Newton's active set, which the Jacobian cache and the
factor reuse see as they see the faces'. The tangent depends on the stress (K = p'/kappa), so the Jacobian is
assembled anew at every Newton iteration while such cells exist.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..effects import logged
from ..physics import elasticity as el
from ..physics import soil as sl
from ..solver.terms import TermDefaults
from . import blocks, measures
from .columns import SoilColumns
from .cells import SoilCells
from .history import SoilLoad, SoilMemory

ON_CAP = 1e-9   # relative: a cell whose mean effective stress is within this share of its preconsolidation is on it


class SoilTerm(TermDefaults):
    """The law with memory in the local cells ``soil`` (pfault.soils.cells.SoilCells) of a mesh with ``n_cells``
    local cells: their shape-function gradients and volumes (``grad``, ``vol``, per soil cell), local dofs
    ``dofs`` (n, 12), which of the local dofs are free (``free``), the local-to-global map ``to_global``, the rows
    this rank owns (``owned``: the first and one past the last global row) and the
    reference Lame parameters of the geostatic gravity solve (``lame``, pfault.soils.cells.reference_young) and
    each cell's initial vertical effective stress (``overburden``, Pa: pfault.soils.overburden). Pure in the
    memory; no further Jacobian pattern, nothing to settle, no strain added to cells (TermDefaults)."""

    name = "soils"
    rows = "cell"           # its history's arrays are per cell
    # Newton backtracks on |F| (pfault.solver.setup.LINE_SEARCH): on each branch the stress is exponential in the
    # volumetric strain, with a kink at the cap where the tangent drops by Cr/Cc; a full step from a cell being
    # reloaded below its cap overshoots past it, the soft virgin tangent then sends it far below, and full steps
    # 2-cycle (a clay column reloaded 4 m below its earlier 5 m: |F| 7.8e5, 2.6e6, 7.8e5, ...)
    full_newton_steps = False
    # within a configuration (each cell's branch) its tangent varies only in the cells' moduli (K = p'/kappa or
    # p'/lambda, a factor exp(d eps_v / kappa) between iterates): an iterative solver's AMG set up at one Newton
    # iterate preconditions the next (pfault.solver.policy.PreconditionerReuse)
    moduli_vary_only = True

    def __init__(self, soil: SoilCells, n_cells: int, grad: np.ndarray, vol: np.ndarray, dofs: np.ndarray,
                 free: np.ndarray, to_global: Any, owned: tuple, lame: tuple, overburden: np.ndarray, mpi: Any) -> None:
        self.soil, self.n_cells, self.grad, self.vol, self.mpi = soil, n_cells, grad, vol, mpi
        self.overburden = overburden
        self.dofs = dofs
        self.free = free[dofs]
        g = (to_global(dofs.ravel().astype(PETSc.IntType)).reshape(dofs.shape) if dofs.size
             else np.zeros(dofs.shape, np.int64))
        self.lame = lame
        self.n = len(soil.cells)
        # the part of the cells' tangent stiffness a shear modulus multiplies, constant: kept (1.2 kB per cell)
        self.shear = blocks.shear_stiffness(grad, vol)
        self.matrix_rows = blocks.CellRows(g, self.free, owned)
        self._last: tuple | None = None     # the last step of the law (``step``)

    # -- the operator and the loads ------------------------------------------------------------------
    def add_operator(self, K: Any, blocked: bool) -> None:
        """Nothing: K holds these cells with zero stiffness (their pattern), the term their whole stiffness."""

    def load(self, t: float, cell_dp: np.ndarray | None, alpha: np.ndarray, out: np.ndarray) -> SoilLoad:
        """The cells' pore-pressure change at t (their Biot load is the elastic assembly's, as every cell's)."""
        return SoilLoad(np.zeros(self.n) if cell_dp is None else np.asarray(cell_dp)[self.soil.cells])

    def gravity_load(self, body: np.ndarray, previous: SoilLoad, out: np.ndarray) -> SoilLoad:
        return previous

    def at_rest(self, load: SoilLoad) -> SoilLoad:
        return SoilLoad(np.zeros(self.n))

    # -- histories ---------------------------------------------------------------------------------
    def initial_vertical_stress(self) -> tuple[np.ndarray, np.ndarray]:
        """The cells' initial total vertical stress (at their centroids, where the geostatic start adds the pore
        pressure): their initial vertical effective stress ``overburden`` (the K0 procedure, pfault.soils.overburden)
        less alpha p0. A normally consolidated soil was consolidated under its overburden, and the elastic gravity
        solve's P1 stress scatters by up to rho g h around it (h the cell height) and carries an elastic soil's arching
        near stiff bodies: at Wuxi's size factor 3 it leaves 836 of the 12,477 soil cells beside the ridge without
        compression."""
        s = self.soil
        return s.cells, -self.overburden - s.alpha * s.static_pressure

    def initial_history(self) -> SoilMemory:
        return SoilMemory.empty(self.n)

    def add_initial_operator(self, A: Any, n_local: int) -> np.ndarray:
        """The cells' reference elastic stiffness (the geostatic gravity solve's operator); returns their branch."""
        lam, mu = self.lame
        with logged("pfaultSoilJacobian"):
            self.matrix_rows.add(A, el.stiffness(self.grad, self.vol, lam, mu))
        return np.full(self.n, sl.ELASTIC)

    def prestressed(self, sigma0: np.ndarray, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory) -> SoilMemory:
        """The memory at the initial stress ``sigma0`` (total, per local cell): the effective stress sigma0 + alpha p0 I
        (p0 the hydrostatic pore pressure of the start), the preconsolidation each layer gives (normally
        consolidated by default), no plastic strain. A preconsolidation below a cell's initial stress (or no initial
        compression) is an InputError naming the option, on every rank (collective)."""
        s = self.soil
        stress0 = sigma0[s.cells] + (s.alpha * s.static_pressure)[:, None, None] * np.eye(3)
        sv0 = -stress0[:, 2, 2]
        svc = sv0.copy()
        for k, kind in enumerate(s.kinds):
            at = s.layer == k
            svc[at] = sl.vertical_preconsolidation(kind, s.precon_value[at], sv0[at], s.alpha[at], s.gamma_w)
        measures.check_start(s, self.mpi, sl.below_initial(s.law, stress0, svc))
        law = sl.initial_history(s.law, stress0, svc)
        return SoilMemory(stress0, law, self.strain(x_loc), np.full(self.n, sl.ELASTIC))

    def advanced(self, x_loc: np.ndarray, history: SoilMemory) -> SoilMemory:
        """The memory at the state x_loc, reached from the remembered one along a straight strain path (the law's
        exact step); unchanged in a cell whose strain has not changed."""
        if not history.started:
            return history
        eps = self.strain(x_loc)
        d = eps - history.strain
        moved = np.any(d != 0.0, axis=(1, 2))
        if not np.any(moved):
            # the state it remembers (a step's start after its commit, the measures, fields and columns of a
            # converged state: four of the five calls of a step): no step of the law
            return history
        new, branch, _ = sl.update(self.soil.law, history.law, d)
        if np.all(moved):
            return SoilMemory(history.stress0, new, eps, branch)
        keep = np.where(moved[:, None, None], new.stress, history.law.stress)
        law = sl.SoilHistory(keep, np.where(moved, new.preconsolidation, history.law.preconsolidation),
                             np.where(moved[:, None, None], new.plastic_strain, history.law.plastic_strain))
        return SoilMemory(history.stress0, law, eps, np.where(moved, branch, history.branch))

    def begin_step(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory) -> SoilMemory:
        """The memory at the converged state x_loc, the start of a solve."""
        return self.advanced(x_loc, history)

    def commit(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory) -> SoilMemory:
        """After a converged step: the memory at its state, with the branch each cell took."""
        return self.advanced(x_loc, history)

    # -- the law -----------------------------------------------------------------------------------
    def strain(self, x_loc: np.ndarray) -> np.ndarray:
        """The P1 strain (n,3,3) of every cell of the term at the state x_loc."""
        return blocks.cell_strain(self.grad, x_loc[self.dofs].reshape(-1, 4, 3))

    def step(self, x_loc: np.ndarray, history: SoilMemory, configuration: np.ndarray | None = None) -> tuple:
        """The law's step from the remembered state to x_loc: (law history, branch, tangent). The last step is
        kept, and given again for the same iterate, memory and configuration: SNES asks for the Jacobian at the
        iterate whose residual it has just evaluated (the tangent costs a sixth of the step)."""
        last = self._last
        if (last is not None and last[1] is history and np.array_equal(last[0], x_loc)
                and (last[2] is None if configuration is None else
                     last[2] is not None and np.array_equal(last[2], configuration))):
            return last[3]
        out = sl.update(self.soil.law, history.law, self.strain(x_loc) - history.strain, True, configuration)
        self._last = (np.array(x_loc, copy=True), history, None if configuration is None else
                      np.array(configuration, copy=True), out)
        return out

    def configuration(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory, exact: bool = True
                      ) -> np.ndarray:
        """The branch of every cell at the iterate x_loc (ELASTIC before the initial stress). ``exact``: the branch
        the residual takes; otherwise as reported: compacting on the virgin line by more than round-off
        (measures.REPORT_STRAIN of plastic volumetric strain)."""
        if not history.started:
            return np.full(self.n, sl.ELASTIC)
        new, branch, _ = self.step(x_loc, history)
        if exact:
            return branch
        dlam = -np.trace(new.plastic_strain - history.law.plastic_strain, axis1=1, axis2=2)
        return np.where(dlam > measures.REPORT_STRAIN, sl.VIRGIN, sl.ELASTIC)

    def trial_configuration(self, history: SoilMemory) -> np.ndarray:
        """A step's elastic trial: every cell on its swelling line (the stiffer branch: an unloading step is then
        not overshot, and a loading one is carried further by Newton)."""
        return np.full(self.n, sl.ELASTIC)

    def jacobian_varies(self, configuration: np.ndarray) -> bool:
        """Whether the Jacobian depends on more than the branches (on all ranks): always with cells of the index
        form (K = p'/kappa) or compacting on the virgin line; the storage form's swelling line is linear."""
        law = self.soil.law
        mine = bool(np.any(law.index_form) or np.any(np.asarray(configuration) == sl.VIRGIN))
        return self.mpi.allreduce(mine, op=MPI.LOR)

    def counts(self, configuration: np.ndarray) -> dict:
        """The step record's counts of a configuration: cells compacting on the virgin line and the others, on all
        ranks (collective)."""
        c = self.mpi.allreduce(np.bincount(np.asarray(configuration, np.int64), minlength=2)[:2], op=MPI.SUM)
        return {"cells_virgin": int(c[sl.VIRGIN]), "cells_elastic": int(c[sl.ELASTIC])}

    # -- residual and Jacobian ------------------------------------------------------------------
    def residual(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory, out: np.ndarray,
                 configuration: np.ndarray | None = None) -> None:
        """Add the cells' internal forces V (sigma' - sigma'_0) g_a to the local array ``out`` (none on constrained
        dofs); ``configuration``: the branches to take instead of the iterate's."""
        if not history.started:
            return
        with logged("pfaultSoilResidual"):
            new, _, _ = self.step(x_loc, history, configuration)
            f = blocks.cell_forces(self.grad, self.vol, new.stress - history.stress0) * self.free
            out += np.bincount(self.dofs.ravel(), weights=f.ravel(), minlength=len(out))

    def add_jacobian(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory, J: Any,
                     configuration: np.ndarray | None = None) -> None:
        """Add the cells' consistent tangent stiffness to J (global indices)."""
        if not history.started:
            return
        with logged("pfaultSoilJacobian"):
            _, _, (a, mu) = self.step(x_loc, history, configuration)
            self.matrix_rows.add(J, blocks.tangent_stiffness(self.grad, self.vol, a, mu, self.shear))

    def cell_stress(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory) -> tuple[np.ndarray, np.ndarray]:
        """The cells' effective stress change sigma' - sigma'_0 at x_loc (none before the initial stress: the
        gravity solve's cells are elastic)."""
        if not history.started:
            return np.zeros(0, np.int64), np.zeros((0, 3, 3))
        return self.soil.cells, self.step(x_loc, history)[0].stress - history.stress0

    # -- what is reported ----------------------------------------------------------------------------
    def measures(self, x_loc: np.ndarray, x_rel: np.ndarray, load: SoilLoad, history: SoilMemory,
                 mesh: Any) -> measures.SoilMeasures:
        """The step record's figures per layer (pfault.soils.measures.layer_figures). Collective."""
        return measures.layer_figures(self.soil, self.mpi, self.advanced(x_loc, history), load, self.vol)

    def summary(self, steps: list, mesh: Any) -> dict:
        """summary.json's figures of the materials with memory (pfault.soils.measures.soil_summary)."""
        return measures.soil_summary(self.soil, self.mpi, steps)

    def columns(self, xy: np.ndarray, mesh: Any) -> SoilColumns:
        """The cells' columns under the points xy (pfault.soils.columns.SoilColumns). Collective."""
        return SoilColumns(self, xy, mesh)

    def fields(self, x_total: np.ndarray, x_rel: np.ndarray, load: SoilLoad, history: SoilMemory) -> dict:
        """fields.h5's cell fields (pfault.soils.measures.cell_fields), NaN outside the materials with memory."""
        return {"cells": measures.cell_fields(self.soil, self.n_cells, self.advanced(x_total, history), load)}

    # -- margins to failure (pfault.margins) -----------------------------------------------------------
    def load_rate(self, t: float, cell_dp: np.ndarray | None, cell_rate: np.ndarray, alpha: np.ndarray,
                  out: np.ndarray) -> SoilLoad:
        """The rate of ``load`` per metre of further drawdown (``cell_rate``: Pa/m per local cell). Nothing is
        added to ``out``: the cells' Biot load is the elastic assembly's, and their residual depends on the state
        only (``residual_rate``: TermDefaults). No part of its own has a margin: a layer's critical head and its
        margin are its reports (pfault.soils.measures)."""
        return SoilLoad(np.asarray(cell_rate, float)[self.soil.cells])

    def margin_configuration(self, x_loc: np.ndarray, load: SoilLoad, history: SoilMemory) -> np.ndarray:
        """The branches of the response to a further drawdown from the converged state x_loc: the virgin line in
        the cells on their cap (p' = p'_c to ON_CAP: normally consolidated, or compacting in the last step), which a
        further compression loads inelastically, the swelling line elsewhere. The state's own configuration is the
        swelling line everywhere (no strain since it was reached: ``configuration``), which is the tangent of an
        unloading and Cc/Cr times too stiff for a cell that compacts."""
        if not history.started:
            return np.full(self.n, sl.ELASTIC)
        new, _, _ = self.step(x_loc, history)
        on_cap = sl.mean_stress(new.stress) >= new.preconsolidation * (1.0 - ON_CAP)
        return np.where(on_cap, sl.VIRGIN, sl.ELASTIC)

    # -- the checkpoint ------------------------------------------------------------------------------
    def history_arrays(self, history: SoilMemory) -> dict:
        """The memory per local cell (pfault.soils.history.SoilMemory.arrays)."""
        return history.arrays(self.soil.cells, self.n_cells)

    def restored(self, arrays: dict, x_loc: np.ndarray, load: SoilLoad) -> SoilMemory:
        """The memory of ``arrays`` (``history_arrays``' per local cell), started at the state x_loc."""
        return self.begin_step(x_loc, load, SoilMemory.of_arrays(arrays, self.soil.cells))
