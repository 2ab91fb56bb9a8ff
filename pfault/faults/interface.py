"""Fault interface: the contact laws on the fault faces (pfault.faults.faces), their residual rows and Jacobian
blocks, and each face's history.

The stick/slip/open state of a face is not stored: the semismooth law (``contact.lagrange_rows``) reads it from
the iterate in every evaluation. What a step remembers is its start (``StepStart``: the law's jumps and the
tractions of the last converged state), which the slip increment is measured from. The stabilisation acts on
the tractions' change since the initial state (``t0``), so a closed or stuck face's jump does not depend on
how the loading was cut into steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..effects import logged
from . import contact as ct
from .stabilization import stabilization_pattern, stabilization_rows

ADD = PETSc.InsertMode.ADD_VALUES


@dataclass(frozen=True)
class FaultTopology:
    """Serial (partition-independent) data of all fault faces, built on rank 0 and shared: the fault each face
    belongs to, the stabilisation pairs and matrices, and the stiffness modulus of the face (harmonic mean of
    the Young's moduli of its two cells: the softer side governs the interface)."""
    fault_id: np.ndarray
    pairs: np.ndarray
    pair_S: np.ndarray
    young: np.ndarray


def fault_topology(serial, split, young, nu):
    """FaultTopology of the split faces of the serial mesh (rank 0); ``young``, ``nu``: per serial cell."""
    from .stabilization import stabilization_pairs
    pairs, S = stabilization_pairs(serial, split, young, nu)
    e_minus, e_plus = young[split.minus_cell], young[split.plus_cell]
    return FaultTopology(split.fault_id, pairs, S, 2.0 * e_minus * e_plus / (e_minus + e_plus))


@dataclass(frozen=True)
class StepStart:
    """The converged state a step starts from, for the owned faces: the jumps the laws act on (local frame;
    the stabilised jump on Lagrange faces), the tractions and the states."""
    g: np.ndarray
    t: np.ndarray
    state: np.ndarray

    def trial(self):
        """States of the step's elastic trial: closed faces stuck, open faces open."""
        return np.where(self.state == ct.OPEN, ct.OPEN, ct.STICK)


class FaultInterface:
    """The contact laws of all faults on the faces this rank owns (``faces``, a pfault.faults.faces.FaultFaces):
    their residual rows and Jacobian blocks, and each face's history (initial traction ``t0``, the pore pressure
    its law sees ``pn``, the start of the step ``start``)."""

    def __init__(self, faces, settings, topology, contact):
        self.faces, self.settings, self.contact = faces, settings, contact
        fault_id, pairs, pair_S = topology.fault_id, topology.pairs, topology.pair_S
        nf = faces.nf
        self.t0 = np.zeros((nf, 3))         # initial (prestress) traction, local; loads nothing
        self.pn = np.zeros(nf)              # alpha p at the face: effective traction = t + (pn, 0, 0)
        stab = np.array([s.stabilization and s.method == "lagrange" for s in settings])
        keep = stab[fault_id[pairs[:, 0]]] if len(pairs) else np.zeros(0, bool)
        self.pairs, self.pair_S = pairs[keep], pair_S[keep]
        self.law, self.penalty_law = self._laws(topology.young[faces.face])
        self.t_ref_all = np.zeros((faces.nf_total, 3))     # t0 of all faces (serial order), set by begin_step
        self.start = StepStart(np.zeros((nf, 3)), np.zeros((nf, 3)), np.full(nf, ct.STICK))

    def _laws(self, face_young):
        """Per-face law parameters: the Lagrange law's augmentation, and the penalty stiffness (E/h of the minus
        cell unless given).

        The augmentation is E/h with E the harmonic mean of the two sides' moduli, capped where the
        stabilisation needs it: the law's argument t + c g_stab, with g_stab = g + S_f (dt_nb - dt) / A,
        decreases with the face's own traction once c S_f / A > 1, and a state can then have no solution
        (with S at its full compliance estimate Wuxi had c S_f / A = 3 to 6 at E/h, and Newton cycled between
        open and closed at the opening front or flipped a slip direction every iteration). The cap
        c <= A / (2 lambda_max(S_f)) keeps it increasing; with S at 1 % of the estimate it is inactive on the
        paper-size meshes (c lambda_max(S_f) / A: median 0.05 on Wuxi, 0.19 on Queretaro). The solution does
        not depend on c."""
        coh = np.array([s.cohesion for s in self.settings])[self.faces.fault]
        tphi = np.tan(np.radians([s.friction_angle for s in self.settings]))[self.faces.fault]
        h = np.maximum(self.faces.h, 1e-300)
        c = face_young / h
        if len(self.pairs):
            # S_f: the sum of the face's stabilisation matrices
            S_f = np.zeros((self.faces.nf_total, 3, 3))
            np.add.at(S_f, self.pairs[:, 0], self.pair_S)
            np.add.at(S_f, self.pairs[:, 1], self.pair_S)
            lam = np.linalg.eigvalsh(S_f[self.faces.face])[:, -1] / np.maximum(self.faces.area, 1e-300)
            c = np.where(lam > 0, np.minimum(c, 0.5 / np.maximum(lam, 1e-300)), c)
        law = ct.FaceLaw(self.faces.area, coh, tphi, c, c)
        k = self.faces.young / h
        kn = np.array([s.penalty_normal for s in self.settings])[self.faces.fault]
        kt = np.array([s.penalty_tangential for s in self.settings])[self.faces.fault]
        return law, ct.FaceLaw(self.faces.area, coh, tphi, np.where(kn > 0, kn, k), np.where(kt > 0, kt, k))

    def effective(self, t):
        """Effective tractions (Terzaghi): the multiplier is the total traction; friction and opening act on
        t_N + alpha p."""
        te = np.array(t, dtype=float, copy=True)
        te[:, 0] += self.pn
        return te

    def _penalty(self, gl, state=None):
        """Penalty faces' total traction, its derivative and state (zero rows for Lagrange faces). ``state``:
        the branches to take instead of the return map's (stick or open)."""
        pen = ~self.faces.lagrange
        t = np.zeros((self.faces.nf, 3))
        d = np.zeros((self.faces.nf, 3, 3))
        st = np.full(self.faces.nf, ct.STICK)
        if np.any(pen):
            # the penalty law acts on the effective traction; the faces receive the total one
            t[pen], d[pen], st[pen] = ct.penalty_traction(self.penalty_law[pen], gl[pen], self.start.g[pen],
                                                          self.effective(self.start.t)[pen],
                                                          self.t0[pen, 0] + self.pn[pen],
                                                          None if state is None else state[pen])
            t[pen, 0] -= self.pn[pen]
        return t, d, st

    def tractions(self, x_loc, gl=None, state=None):
        """Total traction of every owned face (local frame): the multiplier, or the penalty law's (in the
        branches ``state`` if given)."""
        if gl is None:
            gl = self.faces.jumps(x_loc)[1]
        t, _, _ = self._penalty(gl, state)
        lag = self.faces.lagrange
        if self.faces.has_lagrange:
            t[lag] = x_loc[self.faces.lm_dofs[lag]]
        return t

    def set_pore_pressure(self, alpha_p):
        """alpha p (Pa, compression positive) at each owned face for the contact laws."""
        self.pn = np.asarray(alpha_p, dtype=float).copy()

    def begin_step(self, x_loc):
        """Record the converged state ``x_loc`` (under the pore pressure it was solved for) as the start of the
        next step."""
        if len(self.pairs):
            self.t_ref_all = self.faces.gather_faces(self.t0)
        gl = self.faces.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl)
        g = np.where(self.faces.lagrange[:, None], self._stabilised(x_loc, gl, t)[0], gl)
        self.start = StepStart(g, t, self.start.state)     # the states are measured from this start
        self.start = StepStart(g, t, self.states(x_loc, exact=True))

    def start_from(self, x_loc, t):
        """Start the faces' laws at the state x_loc from the total tractions ``t`` (owned faces, local frame):
        the initial traction t0 of a geostatic state, or the tractions a checkpoint recorded. A penalty face's
        tangential traction is its history's return map, not a function of its jump; Lagrange faces read
        theirs from their multipliers. Then ``begin_step`` at x_loc (which reads the penalty faces' start only)."""
        self.start = StepStart(self.faces.jumps(x_loc)[1], np.array(t, dtype=float), self.start.state)
        self.begin_step(x_loc)

    def initial_tractions(self, sigma0):
        """Multipliers of the initial state: the prestress of the minus cell projected on the face (local frame;
        the prestress is continuous across a fault in a layered initial state)."""
        tg = np.einsum("nij,nj->ni", sigma0[self.faces.cell], self.faces.normal)
        return np.einsum("nij,nj->ni", self.faces.R, tg)

    # -- states ---------------------------------------------------------------------------------
    def states(self, x_loc, exact=False):
        """Stick/slip/open of every owned face at the iterate x_loc. ``exact``: the branches the residual takes;
        otherwise as reported: a face within round-off (1e-9 E) of a switch counts as closed and stuck."""
        gl = self.faces.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl)
        st = self._penalty(gl)[2]
        gs = self._stabilised(x_loc, gl, t)[0] if self.faces.has_lagrange else gl
        lag = self.faces.lagrange
        if np.any(lag):
            tol = 0.0 if exact else 1e-9 * self.faces.young[lag]
            st[lag] = ct.states(self.law[lag], gs[lag], self.start.g[lag], self.effective(t)[lag], tol)
        return st

    def counts_by_state(self, x_loc):
        st = self.states(x_loc)
        c = self.faces.mpi.allreduce(np.bincount(st, minlength=3), op=MPI.SUM)
        return {name: int(c[i]) for i, name in enumerate(ct.STATE_NAMES)}

    # -- residual and Jacobian ------------------------------------------------------------------
    def _stabilised(self, x_loc, gl, t):
        """Stabilised local jumps of the owned faces (g + S (dt_b - dt_a) / A, dt = t - t0: the change since the
        initial state) and the stabilisation blocks [(owned index, rows, cols, d(A g_stab)/dt)]; ``t``: total
        tractions of the owned faces.

        Measured from the initial state, not from the step's start: a closed face's law then holds its
        stabilised jump at zero, g_N = -S (dt_b - dt_a)_N / A, whatever steps the loading took. Measured from
        the step's start, a proportional loading in 1 and in 40 steps ended 0.76 apart (relative difference of
        the fissure box's opening and slip fields, config/hard/fissure_box.opts), 15 faces in another state."""
        if not len(self.pairs):
            return gl, []
        dt_all = self.faces.gather_faces(t) - self.t_ref_all
        rs, blocks = stabilization_rows(self.pairs, self.pair_S, self.faces.pos, dt_all, self.faces.all_g_lm)
        return gl + rs / np.maximum(self.faces.area, 1e-300)[:, None], blocks

    def _lagrange_terms(self, x_loc, state=None):
        """Owned Lagrange faces: (indices, states, rows, dr/dg, dr/dt, stabilisation blocks). The law takes the
        stabilised jump; its derivative reaches the neighbours' multipliers through the stabilisation blocks.
        ``state`` (owned faces): the branches to take instead of the iterate's (stick or open)."""
        gl = self.faces.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl)
        gs, sblocks = self._stabilised(x_loc, gl, t)
        idx = np.nonzero(self.faces.lagrange)[0]
        st, r, dg, dt = ct.lagrange_rows(self.law[idx], gs[idx], self.start.g[idx], self.effective(t)[idx],
                                         None if state is None else state[idx])
        # d r / d t_b = (d r / d g_stab) S_ab / A of the row face (dg is dr/dg_stab)
        drdgs = np.zeros((self.faces.nf, 3, 3))
        drdgs[idx] = dg / np.maximum(self.faces.area[idx], 1e-300)[:, None, None]
        blocks = []
        for own, rows, cols, vals in sblocks:
            keep = self.faces.lagrange[own]
            if np.any(keep):
                blocks.append((rows[keep], cols[keep], np.einsum("nij,njk->nik", drdgs[own[keep]], vals[keep])))
        return idx, st, r, dg, dt, blocks

    def residual(self, x_loc, out, state=None):
        """Add the interface terms to the local residual array ``out``; returns the owned faces' states.
        ``state``: the faces' branches to take instead of the iterate's (stick or open)."""
        with logged("pfaultFaultResidual"):
            return self._residual(x_loc, out, state)

    def _residual(self, x_loc, out, state):
        gl = self.faces.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl, state)
        # forces on the displacement dofs from the traction change (the initial traction is in equilibrium
        # with the initial stress): minus side -(A/3) R^T dt, plus side +(A/3) R^T dt
        force = np.einsum("nji,nj->ni", self.faces.R, t - self.t0) * (self.faces.area / 3.0)[:, None]
        fu = self.faces.sign[None, :] * np.tile(force, (1, 6)) * self.faces.u_mask
        out += np.bincount(self.faces.u_dofs.ravel(), weights=fu.ravel(), minlength=len(out))
        out_state = self._penalty(gl, state)[2]
        if self.faces.has_lagrange:
            idx, st, r, _, _, _ = self._lagrange_terms(x_loc, state)
            out_state[idx] = st
            out += np.bincount(self.faces.lm_dofs[idx].ravel(), weights=r.ravel(), minlength=len(out))
        return out_state

    def add_jacobian(self, x_loc, J, state=None, glued=False):
        """Add the interface blocks to J (global indices); returns the owned faces' states. ``state``: the
        faces' branches to take instead of the iterate's (stick or open); ``glued``: every face stuck whatever
        x_loc (the penalty and Lagrange laws' stick branches)."""
        with logged("pfaultFaultJacobian"):
            return self._add_jacobian(x_loc, J, state, glued)

    def _add_jacobian(self, x_loc, J, state, glued):
        gl = self.faces.jumps(x_loc)[1]
        _, d, out_state = self._penalty(gl, state)
        if glued:
            law = self.penalty_law
            d = np.stack([law.c_n, law.c_t, law.c_t], axis=1)[:, :, None] * np.eye(3)[None]
            state = np.full(self.faces.nf, ct.STICK)
        if self.faces.has_lagrange:
            idx, st, _, dg, dt, blocks = self._lagrange_terms(x_loc, state)
            out_state[idx] = st
            self._add_lagrange_blocks(J, idx, dg, dt)
            for rows, cols, vals in blocks:
                J.setValuesRCV(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType), vals.reshape(-1, 9), addv=ADD)
        pen = np.nonzero(~self.faces.lagrange)[0]
        if len(pen):
            self._add_penalty_blocks(J, pen, d[pen])
        return out_state

    def add_glued(self, J):
        """Add the interface blocks of glued faults (every face stuck, no jump) to J: the linear operator of
        the gravity state a geostatic scene starts from."""
        self.add_jacobian(np.zeros(self.faces.n_local), J, glued=True)

    def _add_lagrange_blocks(self, J, idx, dg, dt):
        """Blocks of Lagrange faces ``idx``: forces on the displacement rows, d force/d t = sign A/3 R^T, and the
        constraint rows' dr/du = dr/dg_loc R (1/3) sign and dr/dt."""
        n = len(idx)
        if n == 0:
            return      # (petsc4py's setValuesRCV divides by the number of rows)
        fc = self.faces
        sign = fc.sign.reshape(6, 3)[:, 0]
        blk = (sign[None, :, None, None] * (fc.area[idx] / 3.0)[:, None, None, None]
               * np.transpose(fc.R[idx], (0, 2, 1))[:, None, :, :]).reshape(n, 18, 3)
        J.setValuesRCV(fc.g_u[idx], fc.g_lm[idx], (blk * fc.u_mask[idx][:, :, None]).reshape(n, 54), addv=ADD)
        drdg = np.einsum("nij,njk->nik", dg, fc.R[idx]) / 3.0
        blk = (sign[None, None, :, None] * drdg[:, :, None, :]).reshape(n, 3, 18) * fc.u_mask[idx][:, None, :]
        J.setValuesRCV(fc.g_lm[idx], fc.g_u[idx], blk.reshape(n, 54), addv=ADD)
        J.setValuesRCV(fc.g_lm[idx], fc.g_lm[idx], dt.reshape(n, 9), addv=ADD)

    def _add_penalty_blocks(self, J, pen, d):
        """Blocks of penalty faces ``pen`` with traction derivative d = dt/dg_loc (n,3,3):
        force = A/3 R^T t(g_loc), g_loc = R (1/3) sum sign u."""
        fc = self.faces
        sign = fc.sign.reshape(6, 3)[:, 0]
        dfdg = np.einsum("nji,njk,nkl->nil", fc.R[pen], d, fc.R[pen]) * (fc.area[pen] / 9.0)[:, None, None]
        blk = sign[None, :, None, None, None] * sign[None, None, None, :, None] * dfdg[:, None, :, None, :]
        mask = fc.u_mask[pen]
        blk = blk.reshape(len(pen), 18, 18) * mask[:, :, None] * mask[:, None, :]
        J.setValuesRCV(fc.g_u[pen], fc.g_u[pen], blk.reshape(len(pen), 324), addv=ADD)

    def jacobian_varies(self, state):
        """Whether the Jacobian depends on the iterate beyond the faces' states (slipping or penalty faces),
        on all ranks."""
        local = bool(np.any(state == ct.SLIP) or np.any(~self.faces.lagrange))
        return self.faces.mpi.allreduce(local, op=MPI.LOR)

    def stabilization_pattern(self):
        """(rows, cols) global index pairs of the stabilisation blocks in rows this rank owns."""
        return stabilization_pattern(self.pairs, self.faces.pos, self.faces.all_g_lm)

    # -- output -----------------------------------------------------------------------------------
    def face_fields(self, x_loc):
        """Per owned face: traction local (3), jump local (3), traction global (3), slip global (3), state."""
        g, gl = self.faces.jumps(x_loc)
        t = self.tractions(x_loc, gl)
        tg = np.einsum("nji,nj->ni", self.faces.R, t)
        slip_global = g - gl[:, :1] * self.faces.normal
        return t, gl, tg, slip_global, self.states(x_loc)
