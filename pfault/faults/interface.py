"""Fault interface: the contact laws on the fault faces (pfault.faults.faces), their residual rows and Jacobian
blocks, and each face's history.

A Lagrange face's law acts on its face-mean jump with the part of the face bubbles of its two cells
(pfault.faults.bubbles, condensed cell by cell): the P0 tractions are then stable without a stabilisation
term, and a stuck face's mean jump is held at zero. The stick/slip/open state of a face is not stored: the
semismooth law (``contact.lagrange_rows``) reads it from the iterate in every evaluation. What a step remembers
is its start (``StepStart``: the law's jumps and the tractions of the last converged state), which the slip
increment is measured from. A face of a candidate surface (pfault.faults.breaking) is held in its stick branch
while intact; which faces are broken is the run's state (pfault.state.State), given here by ``set_broken``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..effects import logged
from . import breaking as br
from . import contact as ct
from .bubbles import CellBubbles
from .faces import FaultFaces

ADD = PETSc.InsertMode.ADD_VALUES


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
class StepStart:
    """The converged state a step starts from, for the owned faces: the jumps the laws act on (local frame),
    the tractions and the states."""
    g: np.ndarray
    t: np.ndarray
    state: np.ndarray

    def trial(self) -> np.ndarray:
        """States of the step's elastic trial: closed faces stuck, open faces open."""
        return np.where(self.state == ct.OPEN, ct.OPEN, ct.STICK)


class FaultInterface:
    """The contact laws of all faults on the faces this rank owns (``faces``): their residual rows and Jacobian
    blocks, and each face's history (initial traction ``t0``, the pore pressure its law sees ``pn``, the start
    of the step ``start``). ``bubbles``: the condensed face bubbles of the faces' cells.

    Every face carries its traction as 3 multipliers, and its rows are the semismooth contact law's; a penalty face's
    law takes its jump less the penalty's compliance (a perturbed Lagrangian, ``_law_jumps``), so both laws act on the
    same jump, with its bubble part, and penalty faces tend to Lagrange faces as their stiffness grows."""

    def __init__(self, faces: FaultFaces, settings: list, topology: FaultTopology, contact: Any,
                 bubbles: CellBubbles) -> None:
        self.faces, self.settings, self.contact, self.bubbles = faces, settings, contact, bubbles
        nf = faces.nf
        self.t0 = np.zeros((nf, 3))         # initial (prestress) traction, local; loads nothing
        self.pn = np.zeros(nf)              # alpha p at the face: effective traction = t + (pn, 0, 0)
        self.strength = br.face_strength(settings, faces.fault)
        self.law, self.penalty_law = self._laws(topology.young[faces.face])
        self.intact = np.zeros(nf, dtype=bool)      # faces held stuck (intact faces of candidate surfaces)
        self.set_broken(self.strength.initially_broken())
        self.start = StepStart(np.zeros((nf, 3)), np.zeros((nf, 3)), np.full(nf, ct.STICK))

    def set_broken(self, broken: np.ndarray) -> None:
        """The owned faces broken: the others are held stuck, a broken face's law has its broken cohesion."""
        self.intact = ~np.asarray(broken, dtype=bool)
        coh = self.strength.law_cohesion(~self.intact)
        self.law, self.penalty_law = replace(self.law, cohesion=coh), replace(self.penalty_law, cohesion=coh)

    def _laws(self, face_young: np.ndarray) -> tuple[ct.FaceLaw, ct.FaceLaw]:
        """Per-face law parameters: the Lagrange law's augmentation E/h (E the harmonic mean of the two sides'
        moduli; the solution does not depend on it), and the penalty stiffness (E/h of the minus cell unless
        given); each fault's tension cut-off (at the cone's apex or at zero)."""
        fc = self.faces
        coh = np.array([s.cohesion for s in self.settings])[fc.fault]
        tphi = np.tan(np.radians([s.friction_angle for s in self.settings]))[fc.fault]
        h = np.maximum(fc.h, 1e-300)
        c = face_young / h
        k = fc.young / h
        kn = np.array([s.penalty_normal for s in self.settings])[fc.fault]
        kt = np.array([s.penalty_tangential for s in self.settings])[fc.fault]
        apex = np.array([s.tension_cutoff == "apex" for s in self.settings], dtype=bool)[fc.fault]
        return (ct.FaceLaw(fc.area, coh, tphi, c, c, apex),
                ct.FaceLaw(fc.area, coh, tphi, np.where(kn > 0, kn, k), np.where(kt > 0, kt, k), apex))

    def effective(self, t: np.ndarray) -> np.ndarray:
        """Effective tractions (Terzaghi): the multiplier is the total traction; friction and opening act on
        t_N + alpha p."""
        te = np.array(t, dtype=float, copy=True)
        te[:, 0] += self.pn
        return te

    def tractions(self, x_loc: np.ndarray) -> np.ndarray:
        """Total traction of every owned face (local frame): its multipliers."""
        return x_loc[self.faces.lm_dofs]

    def law_jumps(self, x_loc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The face-mean jumps (P1 part and bubble part), global and local (nf, 3), of the state x_loc; and the
        total tractions."""
        t = self.tractions(x_loc)
        return (*self._mean_jumps(x_loc, t - self.t0), t)

    def _mean_jumps(self, x_loc: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        gl = self.faces.jumps(x_loc)[1]
        gl = gl + self.bubbles.jump(x_loc, dt) / np.maximum(self.faces.area, 1e-300)[:, None]
        return np.einsum("nji,nj->ni", self.faces.R, gl), gl

    def relative_jumps(self, x_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The face-mean jumps, global and local, of a state relative to the initial one (x_rel: displacements and
        tractions less those of the initial state, which loads nothing), under the loads last set: what is
        reported as opening and slip. The initial state's own: within ``bubbles.unloaded()``."""
        return self._mean_jumps(x_rel, self.tractions(x_rel))

    def _law_jumps(self, x_loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The jumps the laws take (local frame) and the total tractions. A penalty face's is its jump less the
        penalty's compliance, g - (t_eff - t0_eff) / k with t0_eff the initial normal traction (tangential: t_T / k,
        measured from the step's start like g_T): its Lagrange rows then hold t_N = t0_N + k g_N while closed and
        t_T = t_T^n + k dg_T while stuck, and slip along the return map's trial t_T^n + k dg_T, the penalty law."""
        _, gl, t = self.law_jumps(x_loc)
        pen = ~self.faces.lagrange
        if np.any(pen):
            law = self.penalty_law[pen]
            te = self.effective(t[pen])
            te[:, 0] -= self.t0[pen, 0] + self.pn[pen]
            gl[pen] -= te / np.stack([law.c_n, law.c_t, law.c_t], axis=1)
        return gl, t

    def set_pore_pressure(self, alpha_p: np.ndarray) -> None:
        """alpha p (Pa, compression positive) at each owned face for the contact laws."""
        self.pn = np.asarray(alpha_p, dtype=float).copy()

    def begin_step(self, x_loc: np.ndarray) -> None:
        """Record the converged state ``x_loc`` (under the pore pressure it was solved for) as the start of the
        next step."""
        g, t = self._law_jumps(x_loc)
        self.start = StepStart(g, t, self.start.state)     # the states are measured from this start
        self.start = StepStart(g, t, self.states(x_loc, exact=True))

    def start_from(self, x_loc: np.ndarray, t: np.ndarray) -> None:
        """Start the faces' laws at the state x_loc from the total tractions ``t`` (owned faces, local frame; the
        multipliers of x_loc): the initial traction t0 of a geostatic state, or the tractions a checkpoint
        recorded."""
        self.start = StepStart(self._law_jumps(x_loc)[0], np.array(t, dtype=float), self.start.state)
        self.begin_step(x_loc)

    def initial_tractions(self, sigma0: np.ndarray) -> np.ndarray:
        """Multipliers of the initial state: the prestress of the minus cell projected on the face (local frame;
        the prestress is continuous across a fault in a layered initial state)."""
        tg = np.einsum("nij,nj->ni", sigma0[self.faces.cell], self.faces.normal)
        return np.einsum("nij,nj->ni", self.faces.R, tg)

    # -- states ---------------------------------------------------------------------------------
    def states(self, x_loc: np.ndarray, exact: bool = False) -> np.ndarray:
        """Stick/slip/open of every owned face at the iterate x_loc. ``exact``: the branches the residual takes;
        otherwise as reported: a face within round-off (1e-9 E) of a switch counts as closed and stuck."""
        return self._law_terms(x_loc, tol=0.0 if exact else 1e-9)[0]

    def counts_by_state(self, x_loc: np.ndarray) -> dict:
        st = self.states(x_loc)
        c = self.faces.mpi.allreduce(np.bincount(st, minlength=3), op=MPI.SUM)
        return {name: int(c[i]) for i, name in enumerate(ct.STATE_NAMES)}

    # -- residual and Jacobian ------------------------------------------------------------------
    def _law_terms(self, x_loc: np.ndarray, state: np.ndarray | None = None, tol: float = 0.0) -> tuple:
        """Every owned face's (state, rows r, dr/dg, dr/dt) (forces, local frame; g the face-mean jump with its
        bubble part): the semismooth Lagrange rows on the jumps of ``_law_jumps``, whose penalty faces' part in t
        adds to dr/dt. ``state``: the branches to take instead of the iterate's; ``tol``: relative to E, the
        states' reporting tolerance (``states``)."""
        fc = self.faces
        gl, t = self._law_jumps(x_loc)
        if tol > 0:
            st = ct.states(self.law, gl, self.start.g, self.effective(t), tol * fc.young)
            return np.where(self.intact, ct.STICK, st), None, None, None
        if np.any(self.intact):
            # intact faces glued: their stick rows whatever the iterate
            st = ct.states(self.law, gl, self.start.g, self.effective(t)) if state is None else state
            state = np.where(self.intact, ct.STICK, st)
        st, r, dg, dt = ct.lagrange_rows(self.law, gl, self.start.g, self.effective(t), state)
        pen = ~fc.lagrange
        if np.any(pen):
            law = self.penalty_law[pen]
            dt[pen] -= dg[pen] / np.stack([law.c_n, law.c_t, law.c_t], axis=1)[:, None, :]
        return st, r, dg, dt

    def residual(self, x_loc: np.ndarray, out: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
        """Add the interface terms to the local residual array ``out``; returns the owned faces' states.
        ``state``: the faces' branches to take instead of the iterate's (stick or open)."""
        with logged("pfaultFaultResidual"):
            fc = self.faces
            dt = self.tractions(x_loc) - self.t0
            # forces on the displacement dofs from the traction change (the initial traction is in equilibrium
            # with the initial stress): minus side -(A/3) R^T dt, plus side +(A/3) R^T dt; and through the bubbles
            force = np.einsum("nji,nj->ni", fc.R, dt) * (fc.area / 3.0)[:, None]
            fu = fc.dofs.sign[None, :] * np.tile(force, (1, 6)) * fc.dofs.u_free
            out += np.bincount(fc.dofs.u.ravel(), weights=fu.ravel(), minlength=len(out))
            self.bubbles.forces(dt, out)
            st, r, _, _ = self._law_terms(x_loc, state)
            out += np.bincount(fc.lm_dofs.ravel(), weights=r.ravel(), minlength=len(out))
            return st

    def add_jacobian(self, x_loc: np.ndarray, J: Any, state: np.ndarray | None = None, glued: bool = False
                     ) -> np.ndarray:
        """Add the interface blocks to J (global indices); returns the owned faces' states. ``state``: the
        faces' branches to take instead of the iterate's (stick or open); ``glued``: every face stuck whatever
        x_loc (the laws' stick branches)."""
        with logged("pfaultFaultJacobian"):
            if glued:
                state = np.full(self.faces.nf, ct.STICK)
            st, _, dg, dt = self._law_terms(x_loc, state)
            self._add_blocks(J, dg, dt)
            return st

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

    def set_bubble_load(self, fb: np.ndarray, out: np.ndarray) -> None:
        """Take fb as the bubbles' load (pfault.faults.bubbles.CellBubbles.set_load) and add its condensed
        displacement load to the local array ``out``."""
        self.bubbles.set_load(fb, out)

    def add_glued(self, J: Any, n_local: int) -> None:
        """Add the interface blocks of glued faults (every face stuck, no jump) to J: the linear operator of
        the gravity state a geostatic scene starts from (``n_local``: the local dofs' number)."""
        self.add_jacobian(np.zeros(n_local), J, glued=True)

    def glued_load(self, out: np.ndarray) -> None:
        """Add to the multiplier rows of the local array ``out`` the right-hand side of the glued faces' rows
        for the bubbles' load last set (their stick rows -c A g, with the load's part of A g)."""
        law = self.law
        out[self.faces.lm_dofs] += np.stack([law.c_n, law.c_t, law.c_t], axis=1) * self.bubbles.jump_of_load()

    def _add_blocks(self, J: Any, dg: np.ndarray, dt: np.ndarray) -> None:
        """The faces' blocks: forces on the displacement rows, d force/d t = sign A/3 R^T, and the rows'
        dr/du = dr/dg_loc R (1/3) sign and dr/dt; then those through the bubbles."""
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

    def jacobian_varies(self, state: np.ndarray) -> bool:
        """Whether the Jacobian depends on the iterate beyond the faces' states (slipping faces), on all ranks.
        Penalty faces' rows are the Lagrange rows on a jump affine in the tractions: as those, affine per state."""
        local = bool(np.any(state == ct.SLIP))
        return self.faces.mpi.allreduce(local, op=MPI.LOR)

    def pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) global index pairs of the bubbles' blocks (rows of any rank)."""
        (f, dofs), (fa, fb) = self.bubbles.pattern()
        g_lm, gd = self.faces.dofs.g_lm, self.bubbles.g_dofs(dofs)
        rows = [np.repeat(g_lm[f], 12, axis=1), np.repeat(gd, 3, axis=1), np.repeat(g_lm[fa], 3, axis=1)]
        cols = [np.tile(gd, (1, 3)), np.tile(g_lm[f], (1, 12)), np.tile(g_lm[fb], (1, 3))]
        return (np.concatenate([r.ravel() for r in rows]).astype(np.int64),
                np.concatenate([c.ravel() for c in cols]).astype(np.int64))

    # -- output -----------------------------------------------------------------------------------
    def face_fields(self, x_loc: np.ndarray) -> tuple:
        """Per owned face: traction local (3), jump local (3), traction global (3), slip global (3), state. The
        jump is the one the law acts on: the face-mean jump with its bubble part."""
        g, gl, t = self.law_jumps(x_loc)
        tg = np.einsum("nji,nj->ni", self.faces.R, t)
        slip_global = g - gl[:, :1] * self.faces.normal
        return t, gl, tg, slip_global, self.states(x_loc)
