"""The faults as a term of the equations: the contact laws on the fault faces (pfault.faults.faces), their
residual rows and Jacobian blocks, given each face's history (pfault.faults.history) and returning the next.

A Lagrange face's law acts on its face-mean jump with the part of the face bubbles of its two cells
(pfault.faults.bubbles, condensed cell by cell): the P0 tractions are then stable without a stabilisation
term, and a stuck face's mean jump is held at zero. The stick/slip/open state of a face is not stored: the
semismooth law (``contact.lagrange_rows``) reads it from the iterate in every evaluation. What a solve remembers
is its start (the law's jumps of the last converged state), which the slip increment is measured from. A face of
a candidate surface (pfault.faults.breaking) is held in its stick branch while intact.

Every face carries its traction as 3 multipliers, and its rows are the semismooth contact law's; a penalty face's
law takes its jump less the penalty's compliance (a perturbed Lagrangian, ``law_jumps``), so both laws act on the
same jump, with its bubble part, and penalty faces tend to Lagrange faces as their stiffness grows.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from mpi4py import MPI

from ..effects import logged
from ..solver.terms import TermDefaults
from . import blocks
from . import breaking as br
from . import contact as ct
from . import margins as fm
from .bubbles import CellBubbles
from .faces import FaultFaces
from .history import FacePressure, FaultHistory, FaultLoad, StepStart
from .measures import FaultMeasures, broken_figures, face_fields, fault_figures, fault_summary, state_counts

REPORT_TOLERANCE = 1e-9     # a face within this share of E (Pa) of a switch is reported closed and stuck


@dataclass(frozen=True)
class FaultTopology:
    """Serial (partition-independent) data of all fault faces, built on rank 0 and shared: the fault each face
    belongs to and the stiffness modulus of the face (harmonic mean of the Young's moduli of its two cells: the
    softer side governs the interface)."""
    fault_id: np.ndarray
    young: np.ndarray


def fault_topology(serial: Any, split: Any, young: np.ndarray) -> FaultTopology:
    """FaultTopology of the split faces of the serial mesh (rank 0); ``young``: per serial cell."""
    e_minus, e_plus = young[split.minus_cell], young[split.plus_cell]
    return FaultTopology(split.fault_id, 2.0 * e_minus * e_plus / (e_minus + e_plus))


@dataclass(frozen=True)
class FaceLaws:
    """Per-face law parameters: the Lagrange law (augmentation E/h, E the harmonic mean of the two sides' moduli;
    the solution does not depend on it), the penalty law (stiffness E/h of the minus cell unless given), with the
    cohesion of an unbroken face and each fault's tension cut-off (at the cone's apex or at zero); and the faces'
    strength (pfault.faults.breaking)."""
    lagrange: ct.FaceLaw
    penalty: ct.FaceLaw
    strength: br.FaceStrength

    def of(self, broken: np.ndarray) -> tuple[ct.FaceLaw, ct.FaceLaw]:
        """The laws with the faces ``broken`` broken: a broken face's law has its broken cohesion (an intact face
        is held stuck: its law's cohesion is unused)."""
        coh = self.strength.law_cohesion(broken)
        return replace(self.lagrange, cohesion=coh), replace(self.penalty, cohesion=coh)


def face_laws(faces: FaultFaces, settings: list, face_young: np.ndarray) -> FaceLaws:
    coh = np.array([s.cohesion for s in settings])[faces.fault]
    tphi = np.tan(np.radians([s.friction_angle for s in settings]))[faces.fault]
    h = np.maximum(faces.h, 1e-300)
    c = face_young / h
    k = faces.young / h
    kn = np.array([s.penalty_normal for s in settings])[faces.fault]
    kt = np.array([s.penalty_tangential for s in settings])[faces.fault]
    apex = np.array([s.tension_cutoff == "apex" for s in settings], dtype=bool)[faces.fault]
    return FaceLaws(ct.FaceLaw(faces.area, coh, tphi, c, c, apex),
                    ct.FaceLaw(faces.area, coh, tphi, np.where(kn > 0, kn, k), np.where(kt > 0, kt, k), apex),
                    br.face_strength(settings, faces.fault))


class FaultTerm(fm.MarginHooks, TermDefaults):
    """The contact laws of all faults on the faces this rank owns (``faces``), with the condensed face bubbles
    of their cells (``bubbles``) and the pore pressure their laws see (``pressure``). Pure in the history: every
    method takes the faces' history and load and returns values or the next history. ``settings``: the faults'
    (pfault.faults.settings.FaultSettings, in the scene's order). Its margins to failure: fm.MarginHooks."""

    name = "faults"
    rows = "face"           # its history's arrays are per fault face

    def __init__(self, faces: FaultFaces, settings: list, topology: FaultTopology, bubbles: CellBubbles,
                 pressure: FacePressure) -> None:
        self.faces, self.settings, self.bubbles, self.pressure = faces, settings, bubbles, pressure
        self.laws = face_laws(faces, settings, topology.young[faces.face])
        self.blocks = blocks.FaceBlocks(faces, bubbles)

    # -- the operator and the loads ------------------------------------------------------------------
    def add_operator(self, K: Any, blocked: bool) -> None:
        """What the term adds to the constant operator (the condensed bubbles' stiffness) and the pattern of the
        faces' blocks within their cells' vertices."""
        self.blocks.add_stiffness(K, blocked)
        self.faces.insert_pattern(K)

    def pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) global index pairs of the bubbles' blocks (rows of any rank)."""
        return self.blocks.pattern()

    def load(self, t: float, cell_dp: np.ndarray | None, alpha: np.ndarray, out: np.ndarray) -> FaultLoad:
        """The faces' load at time t for the pore-pressure change per local cell ``cell_dp`` (None: no change;
        ``alpha`` the cells' Biot coefficient): the Biot load of the bubbles (alpha dp div(phi) is not zero),
        whose condensed load is added to the local array ``out``, and the pore pressure of the laws."""
        fb = (self.bubbles.pore_pressure_load(alpha * cell_dp) if cell_dp is not None
              else np.zeros_like(self.bubbles.zero_load().fb))
        return FaultLoad(self.pressure.at(t, cell_dp), self.bubbles.load(fb, out))

    def gravity_load(self, body: np.ndarray, previous: FaultLoad, out: np.ndarray) -> FaultLoad:
        """The load of the glued gravity state (``body``: force per volume per local cell, nc x 3): the bubbles'
        condensed load added to ``out``, and the right-hand side of the glued faces' stick rows (-c A g with the
        load's part of A g) added to their multiplier rows; the laws' pore pressure that of ``previous``."""
        load = self.bubbles.load(self.bubbles.body_load(body), out)
        law = self.laws.lagrange
        out[self.faces.lm_dofs] += np.stack([law.c_n, law.c_t, law.c_t], axis=1) * self.bubbles.jump_of_load(load)
        return FaultLoad(previous.pn, load)

    def at_rest(self, load: FaultLoad) -> FaultLoad:
        """``load`` without its bubbles' part: the initial state's, which loads nothing."""
        return replace(load, bubbles=self.bubbles.zero_load())

    # -- histories ---------------------------------------------------------------------------------
    def initial_history(self) -> FaultHistory:
        """Before any load: pre-existing faults broken, candidate surfaces intact."""
        return FaultHistory.new(self.laws.strength.initially_broken())

    def add_initial_operator(self, A: Any, n_local: int) -> np.ndarray:
        """The faults' blocks of the initial (geostatic) state's linear operator: every face glued (stuck; the
        stick rows do not depend on the state, the load or the cohesion; ``n_local``: the local dofs' number).
        Returns the faces' states of these blocks."""
        nf = self.faces.nf
        with logged("pfaultFaultJacobian"):
            glued = FaultHistory.new(np.ones(nf, dtype=bool))
            load = FaultLoad(np.zeros(nf), self.bubbles.zero_load())
            _, _, dg, dt = self.law_terms(np.zeros(n_local), load, glued, np.full(nf, ct.STICK))
            self.blocks.add(A, dg, dt)
        return np.full(nf, ct.STICK)

    def prestressed(self, sigma0: np.ndarray, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory
                    ) -> FaultHistory:
        """The faces start from the initial stress ``sigma0`` (cells x 3 x 3): their multipliers in ``x_loc`` (changed
        in place) and initial tractions are the prestress of the minus cell projected on the face (local frame;
        continuous across a fault in a layered initial state)."""
        tg = np.einsum("nij,nj->ni", sigma0[self.faces.cell], self.faces.normal)
        t0 = np.einsum("nij,nj->ni", self.faces.R, tg)
        x_loc[self.faces.lm_dofs] = t0
        return self.begin_step(x_loc, load, replace(history, t0=t0))

    def begin_step(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory) -> FaultHistory:
        """The history with the converged state ``x_loc`` (under the load it was solved for) as the start of a
        solve."""
        gl, _ = self.law_jumps(x_loc, load, history)
        start = replace(history, start=StepStart(gl, history.start.state))    # the states measured from it
        return replace(start, start=StepStart(gl, self.configuration(x_loc, load, start)))

    def commit(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory) -> FaultHistory:
        """After a converged step: the faces slipping or open now have slid."""
        return replace(history, slid=history.slid | (self.configuration(x_loc, load, history, exact=False)
                                                     != ct.STICK))

    def settle(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory, t: float, error: float = 0.0
               ) -> tuple[FaultHistory, int | None]:
        """At time t: the intact faces whose traction at x_loc exceeds their strength break (``settled``; the set
        depends on each face's own traction only). ``error``: a bound on the error of each traction component at
        x_loc (Pa, ``settle_change``'s norm; 0 at a converged state). Collective."""
        return settled(self.faces.mpi, self.laws.strength, load.effective(self.tractions(x_loc)), history, t, error)

    def settle_change(self, dx_loc: np.ndarray) -> float:
        """The size of a change dx_loc of the iterate in what ``settle`` reads: the largest change of a face's
        traction component (Pa) on all ranks."""
        d = dx_loc[self.faces.lm_dofs]
        return self.faces.mpi.allreduce(float(np.abs(d).max()) if d.size else 0.0, op=MPI.MAX)

    # -- the laws ----------------------------------------------------------------------------------
    def tractions(self, x_loc: np.ndarray) -> np.ndarray:
        """Total traction of every owned face (local frame): its multipliers."""
        return x_loc[self.faces.lm_dofs]

    def mean_jumps(self, x_loc: np.ndarray, dt: np.ndarray, load: FaultLoad) -> tuple[np.ndarray, np.ndarray]:
        """The face-mean jumps (P1 part and bubble part), global and local (nf, 3), for the tractions' changes dt
        since the initial state."""
        gl = self.faces.jumps(x_loc)[1]
        gl = gl + self.bubbles.jump(x_loc, dt, load.bubbles) / np.maximum(self.faces.area, 1e-300)[:, None]
        return np.einsum("nji,nj->ni", self.faces.R, gl), gl

    def law_jumps(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The jumps the laws take (local frame) and the total tractions. A penalty face's is its jump less the
        penalty's compliance (pfault.faults.contact.penalty_jump), which makes its Lagrange rows the penalty law."""
        t = self.tractions(x_loc)
        _, gl = self.mean_jumps(x_loc, t - history.t0, load)
        pen = ~self.faces.lagrange
        if np.any(pen):
            gl[pen] = ct.penalty_jump(self.laws.penalty[pen], gl[pen], load.effective(t[pen]),
                                      history.t0[pen, 0] + load.pn[pen])
        return gl, t

    def configuration(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory, exact: bool = True
                      ) -> np.ndarray:
        """Stick/slip/open of every owned face at the iterate x_loc. ``exact``: the branches the residual takes;
        otherwise as reported: a face within round-off (REPORT_TOLERANCE E) of a switch counts as closed and
        stuck."""
        if exact:
            return self.law_terms(x_loc, load, history)[0]
        gl, t = self.law_jumps(x_loc, load, history)
        law = self.laws.of(history.broken)[0]
        st = ct.states(law, gl, history.start.g, load.effective(t), REPORT_TOLERANCE * self.faces.young)
        return np.where(history.broken, st, ct.STICK)

    def trial_configuration(self, history: FaultHistory) -> np.ndarray:
        return history.start.trial()

    def law_terms(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory,
                  state: np.ndarray | None = None) -> tuple:
        """Every owned face's (state, rows r, dr/dg, dr/dt) (forces, local frame; g the face-mean jump with its
        bubble part): the semismooth Lagrange rows on the jumps of ``law_jumps``, whose penalty faces' part in t
        adds to dr/dt. ``state``: the branches to take instead of the iterate's."""
        gl, t = self.law_jumps(x_loc, load, history)
        law, penalty = self.laws.of(history.broken)
        intact = ~history.broken
        if np.any(intact):
            # intact faces glued: their stick rows whatever the iterate
            st = ct.states(law, gl, history.start.g, load.effective(t)) if state is None else state
            state = np.where(intact, ct.STICK, st)
        st, r, dg, dt = ct.lagrange_rows(law, gl, history.start.g, load.effective(t), state)
        pen = ~self.faces.lagrange
        if np.any(pen):
            p = penalty[pen]
            dt[pen] -= dg[pen] / np.stack([p.c_n, p.c_t, p.c_t], axis=1)[:, None, :]
        return st, r, dg, dt

    def counts(self, state: np.ndarray) -> dict:
        """The faces stuck, slipping and open in ``state`` on all ranks (collective)."""
        return state_counts(self.faces.mpi, np.asarray(state, np.int64))

    def jacobian_varies(self, state: np.ndarray) -> bool:
        """Whether the Jacobian depends on the iterate beyond the faces' states (slipping faces), on all ranks.
        Penalty faces' rows are the Lagrange rows on a jump affine in the tractions: as those, affine per state."""
        return self.faces.mpi.allreduce(bool(np.any(state == ct.SLIP)), op=MPI.LOR)

    # -- residual and Jacobian ------------------------------------------------------------------
    def residual(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory, out: np.ndarray,
                 state: np.ndarray | None = None) -> None:
        """Add the faces' terms to the local residual array ``out``. ``state``: the faces' branches to take instead
        of the iterate's (stick or open)."""
        with logged("pfaultFaultResidual"):
            dt = self.tractions(x_loc) - history.t0
            self.blocks.traction_forces(dt, out)
            _, r, _, _ = self.law_terms(x_loc, load, history, state)
            out += np.bincount(self.faces.lm_dofs.ravel(), weights=r.ravel(), minlength=len(out))

    def add_jacobian(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory, J: Any,
                     state: np.ndarray | None = None) -> None:
        """Add the faces' blocks to J (global indices). ``state``: the faces' branches to take instead of the
        iterate's (stick or open)."""
        with logged("pfaultFaultJacobian"):
            _, _, dg, dt = self.law_terms(x_loc, load, history, state)
            self.blocks.add(J, dg, dt)

    def added_stress(self, x_loc: np.ndarray, load: FaultLoad, history: FaultHistory
                     ) -> tuple[np.ndarray, np.ndarray]:
        """The local cells beside the faces and the stress their bubbles add to each (the bubbles' strain averaged
        over the cell in the bubbles' moduli, pfault.faults.bubbles.CellBubbles.cell_stress), recovered from the
        state x_loc under ``load``."""
        dt = self.tractions(x_loc) - history.t0
        return self.bubbles.cell, self.bubbles.cell_stress(x_loc, dt, load.bubbles)

    # -- what is reported ----------------------------------------------------------------------------
    def measures(self, x_loc: np.ndarray, x_rel: np.ndarray, load: FaultLoad, history: FaultHistory,
                 mesh: Any) -> FaultMeasures:
        """The step record's figures of the faults (pfault.faults.measures.fault_figures) at the state x_loc,
        its jumps relative to the initial state from x_rel; ``mesh``: the local mesh (its land surface).
        Collective."""
        states = self.configuration(x_loc, load, history, exact=False)
        _, gl = self.mean_jumps(x_rel, self.tractions(x_rel), load)
        broken = broken_figures(self.faces, len(self.settings), mesh.vert_data[:, 1] == 1, mesh.coords,
                                history.broken, history.break_time)
        return fault_figures(self.faces, [f.name for f in self.settings], states, history.slid, gl, broken)

    def summary(self, steps: list, mesh: Any) -> dict:
        """summary.json's ``faults`` from the step records ``steps`` (pfault.faults.measures.fault_summary)."""
        return fault_summary(self.faces, [f.name for f in self.settings], mesh.coords, mesh.cells, steps)

    def fields(self, x_total: np.ndarray, x_rel: np.ndarray, load: FaultLoad, history: FaultHistory) -> dict:
        """The output series' fields: fault.h5's of the owned faces (pfault.faults.measures.face_fields)."""
        return {"fault": face_fields(self, x_total, x_rel, load, history, history.slid)}

    # -- the checkpoint ------------------------------------------------------------------------------
    def history_arrays(self, history: FaultHistory) -> dict:
        """The history's arrays per owned face (the checkpoint's ``faults/...``): the initial traction (Pa, local
        frame), whether each face has slid and is broken (1 or 0), and when it broke (s, NaN while intact)."""
        return {"t0": np.asarray(history.t0, dtype=float), "slid": history.slid.astype(float),
                "broken": history.broken.astype(float), "break_time": np.asarray(history.break_time, dtype=float)}

    def restored(self, arrays: dict, x_loc: np.ndarray, load: FaultLoad) -> FaultHistory:
        """The history of ``arrays`` (``history_arrays``' per owned face; without ``broken``, a checkpoint written
        before candidate surfaces: every face broken), started at the state x_loc under ``load``."""
        nf = self.faces.nf
        broken = arrays["broken"] > 0.5 if "broken" in arrays else np.ones(nf, dtype=bool)
        history = replace(FaultHistory.new(broken), t0=np.array(arrays["t0"], dtype=float),
                          slid=arrays["slid"] > 0.5,
                          break_time=np.array(arrays["break_time"], dtype=float) if "broken" in arrays
                          else np.full(nf, np.nan))
        return self.begin_step(x_loc, load, history)


def settled(mpi: Any, strength: br.FaceStrength, t_eff: np.ndarray, history: FaultHistory, t: float, error: float
            ) -> tuple[FaultHistory, int | None]:
    """FaultTerm.settle at the owned faces' effective tractions t_eff: the history with the intact faces that
    exceed their strength (pfault.faults.breaking) broken at time t and their number on all ranks, or the history
    and None where ``error`` (a bound on the error of each traction component, Pa) leaves a face's verdict open
    on some rank: then nothing breaks. Collective."""
    new, undecided = br.verdicts(strength, t_eff, history.broken, error)
    n, n_open = mpi.allreduce(np.array([np.count_nonzero(new), np.count_nonzero(undecided)]), op=MPI.SUM)
    if n_open:
        return history, None
    return (history.with_breaks(new, t) if n else history), int(n)
