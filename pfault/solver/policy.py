"""How the equations are solved: the SNES and its KSP, the predictor of a step, the reuse of a direct solver's
factors, the tolerances and the cutting of a step that fails. The equations themselves are
``pfault.solver.equations``'s; the code defaults of the PETSc options are ``pfault.solver.setup``'s.

Without faults the equations are linear: SNES takes one linear solve per step (ksponly). With faults SNES runs one
semismooth Newton per step, from the step's predictor, the faces' stick/slip/open states read from each iterate.

The policy's constants, each measured where it was chosen:

- ``KSP_ATOL_FRACTION``: a fault step's Krylov solves stop once their true residual is below this fraction of
  the step's nonlinear absolute tolerance (``StepSolver.load_tolerance``; unless -ksp_atol is given); the first
  solve of a step that continues the last one, below this fraction of the residual its Newton step is expected to
  leave (``FirstSolveForcing``).
- ``SINGULAR_MAX_IT``: Krylov iterations allowed to a solve on factors in which MUMPS fixed null pivots
  (``FactorReuse.monitor``).
- ``REUSE_ITERATIONS_PER_FACE``: Krylov iterations on kept factors one changed face is expected to cost
  (``FactorReuse.budget``).
- ``FACTOR_FLOP_RATE``: how many times more flops per second MUMPS's factorisation runs (dense blocks) than an
  FGMRES iteration on its factors (triangular solves and a product with the operator, bound by memory); with it
  MUMPS's flop counts give a factorisation's cost in iterations (``factorisation_cost``). Measured by timing both
  (median over a run's factorisations) on Wuxi at 13.7k, 26k, 46k and 84k unknowns on 2 ranks: 5.1, 7.2, 8.7,
  8.8 (26k on 1 rank: 6.5), calibrated Queretaro at 35k: 9.4; the smaller the fronts the lower, so a small
  problem's factorisation is counted up to 1.6 times too cheap, which only refactors it a little sooner.
- The per-step nonlinear tolerance: unless -snes_atol is given, a fault step converges once |F| <= -snes_rtol
  times the forces of the problem (``StepSolver.load_tolerance``).
- ``VERDICT_CONTRACTION``: the largest contraction of Newton's last two steps at which the terms' verdicts are
  taken at an iterate rather than at convergence (``Settling``).
- ``MARGIN_RTOL``: the margins' linear solve (``StepSolver.solve_response``) stops once its residual is below this
  fraction of its right-hand side (or of -ksp_rtol, if larger). The margins are stated to 1e-4 relative: the state
  they extrapolate, converged to -snes_rtol, already leaves them that far apart between the direct and the iterative
  solver (paper-size Wuxi, 2 ranks: up to 5.2e-4 on a face 0.05 m from slipping). At 1e-6 the response moves them by
  at most 1.5e-5 relative against a solve to 1e-8 (Wuxi, the three output times with faces stuck: 1,874, 1,770 and
  11 faces), in 11 FGMRES iterations instead of 15 (1e-5: 9, 1e-4: 7 and 1.2e-2).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any, Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..effects import event_total
from ..records import Solve, SolveCost, counts_text
from ..petsc_compat import converged_default, reuse_preconditioner, set_lag_preconditioner
from .fieldsplit import FieldSplit
from .setup import apply_solver_defaults, is_direct

KSP_ATOL_FRACTION = 0.1     # Krylov tolerance of a fault step, relative to its nonlinear one
SINGULAR_MAX_IT = 10        # Krylov iterations of a solve on factors with null pivots
REUSE_ITERATIONS_PER_FACE = 6   # Krylov iterations per changed face on kept factors (3 rows, doubled for drift)
FACTOR_FLOP_RATE = 8.0          # MUMPS's factorisation flops per second over an FGMRES iteration's on its factors
VERDICT_CONTRACTION = 0.1       # Newton's contraction below which an iterate's error is estimated from its steps
MARGIN_RTOL = 1e-6              # relative residual of the margins' linear solve (margins to 1e-4 relative)


def factorizations() -> int:
    """Numeric factorisations so far on this rank (PETSc's log events; 0 unless logging is on)."""
    return int(sum(event_total(name, "count") for name in ("MatLUFactorNum", "MatCholFctrNum")))


def pc_setups() -> int:
    """Preconditioner set-ups so far on this rank, a PC inside another's counted too (PETSc's log events; 0 unless
    logging is on). A PC that keeps its preconditioner logs none."""
    return int(event_total("PCSetUp", "count"))


def mumps_factors(pc: Any) -> Any:
    """The factor matrix of ``pc`` if MUMPS factored it (LU or Cholesky), else None."""
    if pc.getType() not in ("lu", "cholesky") or pc.getFactorSolverType() != "mumps":
        return None
    return pc.getFactorMatrix()


def mumps_null_pivots(pc: Any) -> int:
    """Null pivots MUMPS found and fixed in the factors of ``pc`` (INFOG(28); 0 for another factorisation)."""
    F = mumps_factors(pc)
    return 0 if F is None else int(F.getMumpsInfog(28))


class FactorReuse:
    """Keeps a direct solver's factors across Newton iterations while that is cheaper than a new factorisation.

    FGMRES preconditioned by the old factors solves a Jacobian that differs from the factored one by the slipping
    faces' values and the states of a few faces in a few iterations. The factors are kept while the faces whose
    state changed since the factorisation cost fewer iterations (``REUSE_ITERATIONS_PER_FACE`` each) than one
    factorisation, and refactored after a kept solve that took more iterations than one factorisation costs.
    The cost of a factorisation in Krylov iterations is computed from MUMPS's own counts of that factorisation
    (``factorisation_cost``), not timed, of factors ordered alike in every run (pfault.solver.setup's AMF on more
    than one rank): the decisions, and so the answer, are the same in every run of a scene on the same ranks,
    whatever else the machine is doing. Calibrated Queretaro at paper size, 2 ranks: 16 factorisations instead of 27
    (-ksp_type preonly) for the same 30 Newton iterations, 159 s instead of 219 s. Factors with null pivots (a
    singular Jacobian) are never kept; factors of another package than MUMPS are kept only while no face changes
    state."""

    def __init__(self, comm: Any, ksp: Any) -> None:
        self.mpi = comm.tompi4py()
        self.max_it = ksp.getTolerances()[3]        # -ksp_max_it (capped on singular factors)
        self.factor_states: np.ndarray | None = None    # faces' states of the Jacobian last factored
        self.cost: float | None = None              # the last factorisation's cost in Krylov iterations
        self.null_pivots = 0                        # null pivots MUMPS fixed in the factors in use
        self.step_null_pivots = 0                   # the most seen in the step being solved
        self._factored = False                      # a factorisation is due before the next solve
        self._kept_its: int | None = None
        ksp.setMonitor(self.monitor)

    def begin_step(self) -> None:
        self.step_null_pivots = self.null_pivots

    def decide(self, snes: Any, state: np.ndarray) -> None:
        """A new Jacobian with the faces in ``state`` was assembled: keep the factors or refactor (collective)."""
        fs = self.factor_states
        changed = len(state) if fs is None or len(fs) != len(state) else int(np.count_nonzero(fs != state))
        changed = self.mpi.allreduce(changed, op=MPI.SUM)
        keep = fs is not None and changed <= self.budget() and not self.kept_too_long() and not self.null_pivots
        keep = self.mpi.allreduce(keep, op=MPI.LAND)
        snes.getKSP().getPC().setReusePreconditioner(keep)      # for the elastic trial's own solve
        set_lag_preconditioner(snes, -1 if keep else -2)        # SNES sets the PC's flag after this
        if not keep:
            self.factor_states = np.array(state)
            self._factored = True

    def budget(self) -> int:
        """How many faces may differ in state from the factored Jacobian before a new factorisation pays: a
        face's state changes at most its 3 multiplier rows, and FGMRES on the old factors needs about one
        iteration per changed row, doubled for the slipping faces' drift. 0 until a factorisation has been
        counted. (Calibrated Queretaro: a factorisation costs 25-30 iterations; 2 changed faces took 11-13
        iterations, 12 took 35.)"""
        return int(self.cost // REUSE_ITERATIONS_PER_FACE) if self.cost is not None else 0

    def kept_too_long(self) -> bool:
        """The last linear solve on kept factors took more iterations than a factorisation costs."""
        return self.cost is not None and (self._kept_its or 0) > self.cost

    def aside(self) -> int | None:
        """Before a solve outside the steps (the margins'): what ``resume`` needs to forget its iterations."""
        return self._kept_its

    def resume(self, kept: int | None) -> None:
        """After a solve outside the steps: where it ran on kept factors its iterations do not count toward
        refactoring (``kept_too_long``: the last step's solves decide, as without it); where it factored anew the
        new factors are the ones the next step starts on."""
        if self._kept_its is not None:
            self._kept_its = kept

    def monitor(self, ksp: Any, its: int, rnorm: float) -> None:
        """KSP monitor (collective): at the first residual of a solve on new factors, their cost and null pivots;
        counts the iterations of a solve on kept factors."""
        if its == 0:
            fresh = self._factored
            if fresh:
                self.cost = factorisation_cost(ksp)
                self.null_pivots = mumps_null_pivots(ksp.getPC())
            self._factored = False
            # Factors of a singular Jacobian (MUMPS fixes its null pivots: -mat_mumps_icntl_24 1) solve a
            # consistent system in one iteration (two blocks, one held by nothing: 1 in each Newton iteration)
            # and an inconsistent one never: part of the body held by nothing but open faces ran FGMRES to
            # -ksp_max_it (10000 iterations) in every attempt of the step. Such factors are not kept and their
            # solves stop after SINGULAR_MAX_IT iterations; SNES then reports the failed linear solve
            cap = self.max_it if not self.null_pivots else min(self.max_it, SINGULAR_MAX_IT)
            if ksp.getTolerances()[3] != cap:
                ksp.setTolerances(max_it=cap)
            self.step_null_pivots = max(self.step_null_pivots, self.null_pivots)
            self._kept_its = None if fresh else 0
        elif self._kept_its is not None:
            self._kept_its = its


class PreconditionerReuse:
    """Keeps an iterative solver's preconditioner (the fieldsplit's submatrices, its Schur approximation and the
    displacement's AMG hierarchy) across the Newton iterations of a step whose Jacobians differ from the one it was
    set up for in stiffness moduli only: the same configuration (every fault face's state, every soil cell's branch)
    and, where the Jacobian varies within it, only terms whose cells' moduli vary (Term.moduli_vary_only: a soil's
    K = p'/kappa or p'/lambda, which moves by the factor exp(d eps_v / kappa) between Newton iterates, a few per cent
    within a step). Such a preconditioner is spectrally equivalent to a new one (the same constraints, moduli within
    a bounded factor), and FGMRES applies the Jacobian itself, so the solution is the same to the Krylov tolerance;
    a set-up costs about as much as five Krylov iterations at Wuxi's paper size. It is set up anew at a step's first
    Jacobian, whenever a configuration changes, and where a term whose Jacobian carries constraints varies (a
    slipping face: its friction direction). Only scenes with such a term (soils that remember) build it: the others
    set the preconditioner up at every new Jacobian, as before.

    Paper-size Wuxi with soils that remember, 2 ranks: 20 set-ups instead of 27 for the same Newton iterations and
    263 Krylov iterations instead of 262. Kept across steps as well (the stresses, and so the moduli, move by up to
    a factor of 2 over the drawdown near the land surface), the Krylov iterations of steps 5-10 rose from 22-23 to
    25, 28, 31, 33, 36, 38: 57 more iterations for 6 fewer set-ups."""

    step_null_pivots = 0        # (FactorReuse's record: an AMG fixes no null pivots)

    def __init__(self, comm: Any, equations: Any) -> None:
        self.mpi, self.eq = comm.tompi4py(), equations
        self.states: np.ndarray | None = None       # the configuration the preconditioner was set up for

    def begin_step(self) -> None:
        """A step's first Jacobian sets the preconditioner up anew."""
        self.states = None

    def aside(self) -> None:
        """(FactorReuse's: nothing of this reuse counts the margins' solves)"""
        return None

    def resume(self, kept: None) -> None:
        """(FactorReuse's)"""

    def decide(self, snes: Any, states: np.ndarray) -> None:
        """A new Jacobian with the terms in ``states`` was assembled (differing from others of its configuration in
        moduli only where the equations' ``moduli_vary_only`` says so): keep the preconditioner or set it up anew
        (collective)."""
        same = self.states is not None and self.eq.moduli_vary_only and len(self.states) == len(states) and bool(
            np.array_equal(self.states, states))
        keep = self.mpi.allreduce(same, op=MPI.LAND)
        snes.getKSP().getPC().setReusePreconditioner(keep)      # for the elastic trial's and margins' solves
        set_lag_preconditioner(snes, -1 if keep else -2)        # SNES sets the PC's flag after this
        if not keep:
            self.states = np.array(states)


def factorisation_cost(ksp: Any) -> float | None:
    """What the factorisation in ``ksp``'s PC costs in FGMRES iterations on its factors, from MUMPS's counts
    (collective): its flops (RINFOG(3)) over ``FACTOR_FLOP_RATE`` times an iteration's flops (a forward and
    backward solve, 2 per entry of the factors, INFOG(29); a product with the operator, 2 per nonzero). None for
    another factorisation package."""
    F = mumps_factors(ksp.getPC())
    if F is None:
        return None
    entries = F.getMumpsInfog(29)
    entries = -1e6 * entries if entries < 0 else float(entries)      # MUMPS gives millions as negatives
    nnz = ksp.getOperators()[0].getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]
    return F.getMumpsRinfog(3) / (FACTOR_FLOP_RATE * (2.0 * entries + 2.0 * nnz))


class Settling:
    """SNES's convergence test with the terms' settling between Newton iterations: a fault's intact faces whose
    traction exceeds their strength break within the Newton solve of a step, at the step's time, for good.

    The faces that break are those whose traction exceeds their strength at the solution with the faces broken so
    far: each face on its own traction, all of them at once (the fracture front runs a row of faces at a time as
    its load moves on), so the broken set depends neither on the partition nor on the order of the faces. Those
    verdicts are taken at the first iterate where they are settled:

    - at an iterate that SNES's own test (SNESConvergedDefault) finds converged, as they stand;
    - earlier, at an iterate whose error is estimated from Newton's last two steps: where the faces' configuration
      (stick/slip/open) is that of the step that led to the iterate, and that step is smaller than the one before
      by Theta = |dx_j| / |dx_j-1| <= VERDICT_CONTRACTION (sizes in what each term reads, a fault's the largest
      change of a face's traction component), the steps to come sum to at most Theta / (1 - Theta) |dx_j| while
      each shrinks by Theta at least (Newton's shrink faster: quadratically). The verdicts are taken there only
      where that error leaves none open (pfault.faults.breaking.verdicts); the broken set is then the one the
      converged iterate would give.

    When parts changed (faces broke), the test ends the SNES solve (CONVERGED_ITS, ``changed`` > 0) and the policy
    runs Newton again from that iterate with the new history (``StepSolver.newton``): neither the step's predictor
    nor its start is redone, so the faces that slid go on sliding from where they were, and each round has SNES's
    iteration budget and divergence test from its own first residual. The step's solution is that of its load with
    the final broken set, from the step's start: how the broken set was found leaves no trace in it.

    Measured with the verdicts taken early but acted on only at convergence, to compare the two: in 67 rounds
    (config/basin_fault.opts with its fault a candidate surface, T = 20 kPa, c = 50 kPa, c_r = 0, at
    benchmarks/basin_fault_mesh.py's 95 m; a layered basin as benchmarks/candidate_surface.py's; the fissure
    box's cascade of tests/verification/test_breaking.py; config/wuxi_fissure.opts at size factor 2) every early
    verdict was the converged iterate's, taken at the second iterate of its round in 63 of them, at the third in
    4; the steps to come summed to 1.1-38 % of the estimate, the closest face 73 Pa from its threshold.
    benchmarks/candidate_surface.py compares the broken sets and break times with the per-pass scheme's (the step
    solved again at the same load after every row, from an elastic trial and a new start: 6 Newton iterations a
    row on the basin fault, against 2)."""

    def __init__(self, equations: Any, state: Any, monitor: bool = False) -> None:
        self.eq, self.state, self.monitor = equations, state, monitor
        self.mpi = equations.comm.tompi4py()
        self.t = 0.0
        self.changed = 0        # parts changed (faces broken) in the SNES solve that ended, 0 if none
        self._steps: tuple | None = None    # the terms' sizes of Newton's last step
        self._config: np.ndarray | None = None

    def begin(self, t: float) -> None:
        """Before a SNES solve at time t."""
        self.t, self.changed = float(t), 0

    def __call__(self, snes: Any, its: int, norms: tuple[float, float, float]) -> int:
        reason = converged_default(PETSc, snes, its, *norms)
        if reason < 0:
            return reason
        errors = self.iterate_errors(snes, its) if reason == 0 else None
        if reason == 0 and errors is None:
            return reason
        histories, n = self.eq.settle(snes.getSolution(), self.state.histories, self.t, errors)
        if not n:
            return reason
        self.state.histories, self.changed = histories, n
        if self.monitor:
            where = "converged" if errors is None else f"error {max(errors):.3g}"
            PETSc.Sys.Print(f"  settled at newton {its} ({where}): {n} parts changed (faces broke)")
        return int(PETSc.SNES.ConvergedReason.CONVERGED_ITS)

    def iterate_errors(self, snes: Any, its: int) -> tuple | None:
        """The terms' estimated errors at the iterate ``its`` of a SNES solve (in their ``settle_change`` norms;
        see the class), or None where no estimate holds. Collective."""
        x = snes.getSolution()
        config = np.concatenate(self.eq.configuration(x, self.state.histories))
        steps = self.eq.settle_changes(snes.getSolutionUpdate()) if its > 0 else None
        previous, before = self._steps, self._config
        self._steps, self._config = steps, config
        if steps is None or previous is None:
            return None
        same = before is not None and len(before) == len(config) and bool(np.array_equal(before, config))
        if not self.mpi.allreduce(same, op=MPI.LAND):
            return None
        errors = []
        for step, prior in zip(steps, previous):
            if step == 0.0:
                errors.append(0.0)
                continue
            theta = step / prior if prior > 0.0 else np.inf
            if theta > VERDICT_CONTRACTION:
                return None
            errors.append(step * theta / (1.0 - theta))
        return tuple(errors)


class ConfigurationMonitor:
    """SNES's monitor for -pfault_contact_monitor: the terms' configurations at each Newton iterate (a fault's
    faces stuck, slipping and open, a soil's cells compacting on the virgin line) and how many changed since the
    last iterate."""

    def __init__(self, equations: Any, state: Any) -> None:
        self.eq, self.state = equations, state
        self.mpi = equations.comm.tompi4py()
        self.last: np.ndarray | None = None

    def __call__(self, snes: Any, its: int, fnorm: float) -> None:
        x = snes.getSolution()
        st = np.concatenate(self.eq.configuration(x, self.state.histories, exact=False))
        prev = self.last if its > 0 and self.last is not None else st
        changed = self.mpi.allreduce(int(np.count_nonzero(prev != st)), op=MPI.SUM)
        self.last = st
        counts = self.eq.counts(x, self.state.histories)
        what = " and ".join(w for k, w in (("stick", "faces"), ("cells_virgin", "cells")) if k in counts)
        PETSc.Sys.Print(f"  newton {its:2d}  |F| {fnorm:.3e}  {counts_text(counts)}"
                        + (f"  ({changed} {what} changed state)" if its else ""))


class FirstSolveForcing:
    """Inexact Newton on the first Krylov solve of a step that continues the last one: it stops once its residual
    is below KSP_ATOL_FRACTION of the residual the Newton step is expected to leave, the last step's first
    contraction |F_1|/|F_0| times |F_0| (Eisenstat and Walker's forcing term, with the contraction of the step
    before; never tighter than -ksp_rtol). Solving that system to -ksp_rtol buys nothing the Newton step keeps:
    the law's own nonlinearity leaves its remainder (paper-size Wuxi with soils that remember: |F| 3.5e8 ->
    8e5 whatever the linear solve's accuracy beyond 1e-4).

    Only where the step starts from the extrapolated predictor, the last step did too and took a Newton iteration,
    and the first Jacobian's configuration (a fault's faces' states, a soil's cells' branches) is that of the last
    step's last Newton Jacobian: an inexact iterate in a configuration that changes may take other faces to slip
    or open (paper-size Wuxi with Eisenstat and Walker's forcing on every solve: 2 more Newton iterations, 1
    face more slipping after the first year, the largest slip 1.7e-3 apart). Where the equations are affine in
    the configuration the last contraction is round-off, and so is the forcing term."""

    def __init__(self, comm: Any, ksp: Any) -> None:
        self.comm = comm                                # (the KSP is not kept: the step solver destroys it)
        self.rtol = float(ksp.getTolerances()[0])      # -ksp_rtol
        self.contraction: float | None = None          # the last step's first |F_1| / |F_0|
        self.eta: float | None = None                  # this step's first solve's forcing term, until it is used
        self.last: np.ndarray | None = None            # the configuration of the last Newton Jacobian

    def begin_step(self, extrapolated: bool) -> None:
        self.eta = KSP_ATOL_FRACTION * self.contraction if extrapolated and self.contraction is not None else None

    def jacobian(self, snes: Any, states: np.ndarray | None) -> None:
        """After a Newton Jacobian (``states``: its configuration, None where the last one was kept): the
        tolerance of the Krylov solve that follows. Collective."""
        eta, self.eta = self.eta, None
        last = self.last
        if states is not None:
            self.last = states
        if eta is not None and snes.getIterationNumber() == 0:
            same = states is None or (last is not None and states.shape == last.shape
                                      and bool(np.array_equal(states, last)))
            if not self.comm.tompi4py().allreduce(same, op=MPI.LAND):
                eta = None
        snes.getKSP().setTolerances(rtol=max(eta, self.rtol) if eta is not None else self.rtol)

    def end_step(self, snes: Any, out: Solve, extrapolated: bool) -> None:
        h = out.cost.residual_history
        self.contraction = min(h[1] / h[0], 1.0) if extrapolated and out.converged and len(h) > 1 and h[0] > 0 \
            else None
        snes.getKSP().setTolerances(rtol=self.rtol)


class ResponseSolve:
    """The margins' linear solve on a step solver's KSP (``StepSolver.solve_response``), with what the step built."""

    def __init__(self, solver: Any) -> None:
        self.solver = solver

    def solve(self, rhs: Any, du: Any, config: tuple | None = None) -> tuple[bool, SolveCost]:
        """Solve J du = rhs from zero with the Jacobian of the converged state in the terms' configuration ``config``
        (None: the state's; a fault's faces stuck, slipping or open) on the step's KSP. The Krylov solve stops at
        MARGIN_RTOL (or -ksp_rtol, if larger) of |rhs| (the step's absolute tolerance is for its forces). Its
        iterations on kept factors do not count toward the next step's factor reuse (``FactorReuse.aside``): the
        steps solve the same with margins or without. Returns (converged, its cost).

        What the step built is used where it holds (``_operator``): in the configuration of the last
        Newton Jacobian that Jacobian itself when it depends on the configuration only (no slipping face, no soil
        cell on its virgin line), else the Jacobian at the state, preconditioned by the last Newton Jacobian's
        preconditioner; in another configuration (a soil's cells on their cap) a new Jacobian and preconditioner.
        A direct solver's factors are kept when the factor reuse keeps them (``FactorReuse``)."""
        s = self.solver
        eq, t0, nfact, njac, npc = s.eq, time.perf_counter(), factorizations(), s.eq.n_jacobians, pc_setups()
        ksp = s.snes.getKSP()
        pc = ksp.getPC()
        reused = reuse_preconditioner(pc)
        kept = s.reuse.aside() if s.reuse is not None else None
        keep = self._operator(config)
        rtol, atol, divtol, max_it = ksp.getTolerances()
        try:
            if keep:
                pc.setReusePreconditioner(True)
            ksp.setTolerances(rtol=max(rtol, MARGIN_RTOL), atol=0.0)
            ksp.solve(rhs, du)
        finally:
            ksp.setTolerances(rtol=rtol, atol=atol, divtol=divtol, max_it=max_it)
            if keep:
                pc.setReusePreconditioner(reused)
            if s.reuse is not None:
                s.reuse.resume(kept)
        cost = SolveCost(0, int(ksp.getIterationNumber()), time.perf_counter() - t0,
                         int(factorizations() - nfact), int(eq.n_jacobians - njac), pc_setups=pc_setups() - npc)
        return ksp.getConvergedReason() > 0, cost

    def _operator(self, config: tuple | None) -> bool:
        """Put the Jacobian of the converged state in ``config`` into the KSP (assembled only when it differs from
        the one there, ``Equations.assemble_jacobian``); returns whether the preconditioner built for the last
        Jacobian is to be kept: that Jacobian was of the same configuration (collective), so it differs from this
        one by the slipping faces' and compacting cells' values at most, and a Krylov method, not a direct solve
        alone (preonly), runs to the tolerance on the new operator. A direct solver's factors are the factor
        reuse's decision (made in ``_jacobian``)."""
        s = self.solver
        eq = s.eq
        before = eq.jacobian_configuration
        s._jacobian(s.snes, s.state.u, eq.J, eq.J, config or None)
        ksp = s.snes.getKSP()
        ksp.setOperators(eq.J, eq.J)
        after = eq.jacobian_configuration
        same = before is not None and after is not None and len(before) == len(after) and \
            bool(np.array_equal(before, after))
        same = s.comm.tompi4py().allreduce(same, op=MPI.LAND)
        return same and s.reuse is None and ksp.getType() != PETSc.KSP.Type.PREONLY


class StepSolver:
    """Solves the equations for one time after another, advancing ``state``: owns the SNES (created once, code
    defaults where the user is silent, then -snes_*/-ksp_*/-pc_* options), the nonlinear steps' tolerances and
    predictor, and a direct solver's factor reuse. ``monitor``: print the terms' configurations at every Newton
    iterate (-pfault_contact_monitor)."""

    def __init__(self, equations: Any, state: Any, geostatic: bool = False, monitor: bool = False) -> None:
        self.eq, self.state = equations, state
        self.comm = equations.comm
        self.monitor = monitor
        self.F = equations.create_vec()
        self.reuse: FactorReuse | PreconditionerReuse | None = None
        nonlinear = not equations.linear
        if nonlinear:
            PETSc.Log.begin()           # the factorisation count comes from PETSc's log (MatLUFactorNum)
        apply_solver_defaults(linear=equations.linear,
                              full_steps=all(term.full_newton_steps for term in equations.terms))
        opts = PETSc.Options()
        self._atol_user, self._ksp_atol_user = opts.hasName("snes_atol"), opts.hasName("ksp_atol")
        self.snes = snes = PETSc.SNES().create(comm=self.comm)
        snes.setDM(equations.dm)
        snes.getKSP().setDMActive(False)
        snes.setFunction(self._residual, self.F)
        snes.setJacobian(self._newton_jacobian, equations.J, equations.J)
        snes.setFromOptions()
        self.split = FieldSplit(equations, snes.getKSP().getPC())
        self.settling = Settling(equations, state, monitor)
        if nonlinear:
            snes.setConvergenceHistory()
            snes.setConvergenceTest(self.settling)
            if monitor:
                snes.setMonitor(ConfigurationMonitor(equations, state))
        snes.setUp()
        ksp = snes.getKSP()
        ksp.setOperators(equations.J, equations.J)
        self.forcing = FirstSolveForcing(self.comm, ksp)
        if nonlinear:
            if is_direct() and ksp.getType() != "preonly":
                self.reuse = FactorReuse(self.comm, ksp)
            elif not is_direct() and any(term.moduli_vary_only for term in equations.terms):
                self.reuse = PreconditionerReuse(self.comm, equations)
            state.histories = equations.begin_step(state.u, state.histories)
            if geostatic:
                # the glued gravity solve (geostatic) sets the solver up on its own operator first: a
                # factorisation of this Jacobian would be discarded (paper-size Queretaro: 3-4.5 s)
                return
            self._jacobian(snes, state.u, equations.J, equations.J)
        ksp.setUp()

    # -- callbacks -------------------------------------------------------------------------------
    def _residual(self, snes: Any, x: Any, F: Any) -> None:
        self.eq.residual(x, F, self.state.histories)

    def _jacobian(self, snes: Any, x: Any, J: Any, P: Any, config: tuple | None = None) -> np.ndarray | None:
        states = self.eq.assemble_jacobian(x, J, self.state.histories, config)
        if states is not None and self.reuse is not None:
            self.reuse.decide(snes, states)
        return states

    def _newton_jacobian(self, snes: Any, x: Any, J: Any, P: Any) -> None:
        self.forcing.jacobian(snes, self._jacobian(snes, x, J, P))

    # -- linear solves ---------------------------------------------------------------------------------
    def solve_linear(self, A: Any, b: Any, x: Any) -> int:
        """Solve A x = b with the step's KSP and preconditioner (the initial gravity state); returns KSP's
        converged reason."""
        ksp = self.snes.getKSP()
        ksp.setOperators(A, A)
        ksp.solve(b, x)
        return int(ksp.getConvergedReason())

    def solve_response(self, rhs: Any, du: Any, config: tuple | None = None) -> tuple[bool, SolveCost]:
        """The margins' linear solve J du = rhs at the converged state (ResponseSolve)."""
        return ResponseSolve(self).solve(rhs, du, config)

    # -- one step ------------------------------------------------------------------------------------
    def solve_step(self, t: float) -> Solve:
        """Solve for time t from the converged state (at state.time). Nonlinear equations: SNES runs the
        semismooth Newton from the step's predictor (``predict``), the terms settling between its iterations
        (``newton``: a fault's faces that break)."""
        eq, state, snes = self.eq, self.state, self.snes
        nonlinear = not eq.linear
        t0 = time.perf_counter()
        nfact, njac = (factorizations() if nonlinear else 0), eq.n_jacobians
        if self.reuse is not None:
            self.reuse.begin_step()
        trial = start = None
        if nonlinear:
            state.histories = eq.begin_step(state.u, state.histories)    # under the loads it was solved for
            start = state.u.copy()
        eq.loads.set(t)
        if nonlinear:
            self.load_tolerance()
            trial = self.predict(t)
            self.forcing.begin_step(trial is None)
            out = self.newton(t)
            self.forcing.end_step(snes, out, trial is None)
        else:
            snes.solve(None, state.u)
            reason = int(snes.getConvergedReason())
            out = Solve(float(t), reason > 0, reason,
                        SolveCost(int(snes.getIterationNumber()), int(snes.getLinearSolveIterations())))
        out = replace(out, cost=replace(out.cost, wall_s=time.perf_counter() - t0))
        if nonlinear:
            out = self._nonlinear_record(out, trial, nfact, njac)
        if out.converged:
            if start is not None and t > state.time:
                state.set_previous(state.time, start)
            state.time = float(t)
        if start is not None:
            start.destroy()
        return out

    def newton(self, t: float) -> Solve:
        """The semismooth Newton of a step at time t from state.u (SNES), with the terms' settling between its
        iterations (``Settling``): after each round in which faces broke, Newton again from the iterate where they
        broke. The solve's record: SNES's last reason, the rounds' iterations and residual histories, and the
        rounds and faces broken (``breaking``)."""
        snes, settling = self.snes, self.settling
        cost, rounds, changed = SolveCost(), 0, 0
        while True:
            settling.begin(t)
            snes.setConvergenceHistory(reset=True)
            snes.solve(None, self.state.u)
            its = int(snes.getIterationNumber())
            history = tuple(float(v) for v in snes.getConvergenceHistory()[0][:its + 1])
            cost = cost + SolveCost(its, int(snes.getLinearSolveIterations()), residual_history=history)
            if not settling.changed:
                break
            rounds, changed = rounds + 1, changed + settling.changed
        reason = int(snes.getConvergedReason())
        return Solve(float(t), reason > 0, reason, cost, breaking=(rounds, changed))

    def _nonlinear_record(self, out: Solve, trial: tuple | None, nfact: int, njac: int) -> Solve:
        snes, c = self.snes, out.cost
        history = c.residual_history
        newton, krylov, predictor = c.newton_its, c.ksp_its, "extrapolated"
        if trial is not None:
            predictor = "elastic trial"
            newton, krylov, history = newton + 1, krylov + trial[1], (trial[0],) + history
        cost = replace(c, newton_its=newton, ksp_its=krylov, factorizations=int(factorizations() - nfact),
                       jacobians=int(self.eq.n_jacobians - njac), residual_history=history)
        pivots = self.reuse.step_null_pivots if self.reuse is not None else 0
        return replace(out, cost=cost, nonlinear=True, predictor=predictor, atol=float(snes.getTolerances()[1]),
                       null_pivots=int(pivots), counts=self.eq.counts(self.state.u, self.state.histories))

    def predict(self, t: float) -> tuple | None:
        """Move state.u to the step's predictor and return None, or do the elastic trial and return what it
        returns. The predictor extrapolates the last step's increment to t (exact on a proportional loading:
        the faces' states and slip directions carry on); it is kept when its residual is below that of the
        converged state under the new load, and is not when the loading turns (a drawdown that stops, a
        water table that recovers), where the elastic trial starts the step instead."""
        state, eq = self.state, self.eq
        if state.previous is None or not state.previous[0] < state.time < t:
            return self.elastic_trial()
        t_a, u_a = state.previous
        ratio = (t - state.time) / (state.time - t_a)
        u_n = state.u.copy()
        try:
            self._residual(self.snes, state.u, self.F)
            f_start = self.F.norm()
            state.u.axpy(ratio, u_n)
            state.u.axpy(-ratio, u_a)
            self._residual(self.snes, state.u, self.F)
            f_pred = self.F.norm()
            if f_pred < f_start:
                if self.monitor:
                    PETSc.Sys.Print(f"  predictor: extrapolated (|F| {f_pred:.3e} against {f_start:.3e} at the "
                                    "last state)")
                return None
            u_n.copy(state.u)
        finally:
            u_n.destroy()
        if self.monitor:
            PETSc.Sys.Print(f"  predictor: elastic trial (extrapolated |F| {f_pred:.3e} >= {f_start:.3e})")
        return self.elastic_trial()

    def elastic_trial(self) -> tuple:
        """Move state.u to the step's elastic trial: the load increment carried in the configuration the step
        starts in (a fault's closed faces stuck, its open faces open); returns (|F| before, Krylov iterations).
        The semismooth Newton then starts from a state where the increment has been carried elastically, not
        from the last one with the new pore pressure's jump in the faces' effective tractions.

        A trial whose linear solve fails (a singular Jacobian: part of the body held by nothing but open faces)
        leaves u where it was: its iterate is whatever the Krylov method reached, and Newton from there could
        take the faces anywhere (the two blocks started geostatically, every face open: the step converged from
        a trial stopped after SINGULAR_MAX_IT iterations, or failed, depending on the round-off in that
        iterate)."""
        eq, u = self.eq, self.state.u
        config = eq.trial_configuration(self.state.histories)
        eq.residual(u, self.F, self.state.histories, config)
        fnorm = self.F.norm()
        self._jacobian(self.snes, u, eq.J, eq.J, config)
        ksp = self.snes.getKSP()
        ksp.setOperators(eq.J, eq.J)
        du = u.duplicate()
        ksp.solve(self.F, du)
        if ksp.getConvergedReason() > 0:
            u.axpy(-1.0, du)
        du.destroy()
        return fnorm, int(ksp.getIterationNumber())

    def load_tolerance(self) -> None:
        """Unless -snes_atol is given: a step also converges once |F| <= -snes_rtol times the forces of the
        problem: the larger of the load at the step's time |f|, the internal forces of the state it starts from
        |K u| and, in a geostatic scene, the gravity load the initial stress carries. A step that changes
        little starts from a residual near round-off of the previous one; one that changes nothing at zero
        load (a plateau of the drawdown at zero, the heads recovered) has only those forces to scale its
        round-off: its load is zero.

        The Krylov solves of the step stop once their true residual is below KSP_ATOL_FRACTION of that
        tolerance (unless -ksp_atol is given; only for a KSP that measures the true residual, as FGMRES does):
        below it the linear residual no longer decides whether the next iterate converges, and -ksp_rtol 1e-8
        of a residual that is already small asks for digits the step does not need. Calibrated Queretaro: 85
        instead of 138 Krylov iterations on kept factors, the same 36 Newton iterations and 22
        factorisations, the same maxima."""
        eq, snes = self.eq, self.snes
        if not self._atol_user:
            eq.K.mult(self.state.u, self.F)     # F as scratch: the predictor and SNES evaluate the residual next
            scale = max(eq.loads.f.norm(), self.F.norm(), eq.loads.gravity_norm())
            rtol, _, stol, max_it = snes.getTolerances()
            snes.setTolerances(rtol=rtol, atol=max(rtol * scale, 1e-300), stol=stol, max_it=max_it)
        ksp = snes.getKSP()
        if self._ksp_atol_user or ksp.getNormType() != PETSc.KSP.NormType.UNPRECONDITIONED:
            return
        ksp.setTolerances(atol=KSP_ATOL_FRACTION * snes.getTolerances()[1])

    # -- a time interval -----------------------------------------------------------------------------
    def solve_interval(self, t_prev: float, t: float, max_cuts: int = 0) -> Solve:
        """Advance from t_prev to t (the pore-pressure source already advanced to t); a nonlinear step that does
        not converge is cut (``cut_step``)."""
        return cut_step(self.solve_step, self.state, t_prev, t, 0 if self.eq.linear else max_cuts, self.monitor)

    def ksp_types(self) -> tuple[str, str]:
        ksp = self.snes.getKSP()
        return ksp.getType(), ksp.getPC().getType()

    def destroy(self) -> None:
        self.snes.destroy()
        self.split.destroy()
        self.F.destroy()


def cut_step(solve_step: Callable[[float], Solve], state: Any, t_prev: float, t: float, max_cuts: int,
             verbose: bool = False) -> Solve:
    """Advance ``state`` from t_prev to t with ``solve_step``. A step whose Newton solve does not converge is
    retried from the state at t_prev (a snapshot: solution, time, predictor's history, histories) as 2, 4, ...
    equal sub-steps (up to max_cuts halvings); the pore-pressure source gives each sub-step's pressure (a flow
    model's is interpolated linearly in time within the interval). Returns the interval's solve: the last
    attempt's outcome, with the iterations and times of every attempt."""
    if max_cuts <= 0:
        return solve_step(t)
    before = state.snapshot()
    try:
        out = solve_step(t)
        if out.converged:
            return out
        tried, attempt = [out], [out]
        cuts = 0
        while not out.converged and cuts < max_cuts:
            cuts += 1
            n = 2 ** cuts
            state.restore(before)
            if verbose:
                PETSc.Sys.Print(f"  step not converged ({out.reason}): retrying as {n} sub-steps")
            attempt = []
            for k in range(1, n + 1):
                out = solve_step(t_prev + (t - t_prev) * k / n)
                tried.append(out)
                attempt.append(out)
                if not out.converged:
                    break
    finally:
        before.destroy()
    cost = tried[0].cost
    for r in tried[1:]:
        cost = cost + r.cost
    broke = [r.breaking for r in attempt if r.breaking is not None]
    return replace(out, cost=cost, time_s=float(t), substeps=2 ** cuts,
                   null_pivots=max(r.null_pivots for r in tried),
                   breaking=tuple(map(sum, zip(*broke))) if broke else None)
