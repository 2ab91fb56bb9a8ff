"""Fault interface on the distributed mesh: the faces' geometry and dofs, their residual rows and Jacobian blocks.

Every fault face is handled by the rank that owns its minus cell; the face's vertices, with both sides'
displacement dofs, are in that cell's closure, so the interface element is local. Only the stabilisation
couples neighbouring faces, which may sit on other ranks: their multipliers and states are gathered on every
rank (the fault is a surface: O(faces) data).

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
from ..mesh.serial import TET_FACES
from ..physics import elasticity as el
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


def fault_topology(serial, split, materials):
    """FaultTopology of the split faces of the serial mesh (rank 0)."""
    from .stabilization import stabilization_pairs
    pairs, S = stabilization_pairs(serial, split, materials)
    e = np.array([m.young_modulus for m in materials])
    e_minus, e_plus = e[serial.cell_material[split.minus_cell]], e[serial.cell_material[split.plus_cell]]
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
    """Interface terms of all faults for the faces this rank owns."""

    def __init__(self, mesh, dofmap, settings, topology, materials, bc_local, lgmap, contact):
        self.settings, self.contact = settings, contact
        fault_id, pairs, pair_S = topology.fault_id, topology.pairs, topology.pair_S
        self.mpi = mesh.dm.getComm().tompi4py()
        self.nf_total = len(fault_id)
        cells, lfaces = np.nonzero(mesh.cell_fault_face >= 0)
        fid = mesh.cell_fault_face[cells, lfaces]
        order = np.argsort(fid)
        self.face = fid[order]
        self.cell, self.lface = cells[order], lfaces[order]
        nf = self.nf = len(self.face)
        self.fault = fault_id[self.face]
        self.verts = mesh.cells[self.cell[:, None], TET_FACES[self.lface]]
        an = el.triangle_area_normal(mesh.coords[self.verts])   # outward normal of the minus cell: minus -> plus
        self.area = np.linalg.norm(an, axis=1)
        self.normal = an / np.maximum(self.area, 1e-300)[:, None]
        self.R = ct.local_frames(self.normal) if nf else np.zeros((0, 3, 3))
        self.lagrange = np.array([s.method == "lagrange" for s in settings])[self.fault]
        self._dofs(mesh, dofmap, bc_local, lgmap, fault_id)
        self.has_lagrange = any(s.method == "lagrange" for s in settings)
        self.h = np.sqrt(self.area)
        self.young = np.array([m.young_modulus for m in materials])[mesh.cell_material[self.cell]]
        self.t0 = np.zeros((nf, 3))         # initial (prestress) traction, local; loads nothing
        self.pn = np.zeros(nf)              # alpha p at the face: effective traction = t + (pn, 0, 0)
        self._setup_gather()
        stab = np.array([s.stabilization and s.method == "lagrange" for s in settings])
        keep = stab[fault_id[pairs[:, 0]]] if len(pairs) else np.zeros(0, bool)
        self.pairs, self.pair_S = pairs[keep], pair_S[keep]
        self.law, self.penalty_law = self._laws(topology.young[self.face])
        self.pos = np.full(self.nf_total, -1)
        self.pos[self.face] = np.arange(nf)
        self.t_ref_all = np.zeros((self.nf_total, 3))     # t0 of all faces (serial order), set by begin_step
        self.start = StepStart(np.zeros((nf, 3)), np.zeros((nf, 3)), np.full(nf, ct.STICK))

    def _dofs(self, mesh, dofmap, bc_local, lgmap, fault_id):
        nf = self.nf
        self.n_local = dofmap.n_local
        cd = dofmap.cell_dofs.reshape(-1, 4, 3)
        self.minus_dofs = cd[self.cell[:, None], TET_FACES[self.lface]]             # (nf,3,3)
        self.plus_dofs = dofmap.vertex_dofs(1)[self.verts]                            # (nf,3,3)
        # slot of each Lagrange face in its cell's multiplier block (the cell carries 3 dofs per Lagrange face
        # it is the minus cell of, pfault.simulation): its Lagrange faces in local-face order
        lag_fault = np.array([st.method == "lagrange" for st in self.settings])
        slot = np.zeros(nf, np.int64)
        if nf:
            fid = mesh.cell_fault_face[self.cell]
            lag_at = (fid >= 0) & lag_fault[fault_id[np.maximum(fid, 0)]]
            slot = (lag_at & (np.arange(4)[None, :] < self.lface[:, None])).sum(axis=1)
        self.lm_dofs = np.where(self.lagrange[:, None], dofmap.cell_offset[self.cell][:, None] + 3 * slot[:, None]
                                + np.arange(3), -1)
        self.u_dofs = np.concatenate([self.minus_dofs.reshape(nf, 9), self.plus_dofs.reshape(nf, 9)], axis=1)
        self.sign = np.concatenate([-np.ones(9), np.ones(9)])                        # jump = plus - minus
        idx = PETSc.IntType
        self.g_u = lgmap.apply(self.u_dofs.ravel().astype(idx)).reshape(nf, 18) if nf else np.zeros((0, 18), idx)
        self.g_lm = lgmap.apply(self.lm_dofs.ravel().astype(idx)).reshape(nf, 3) if nf else np.zeros((0, 3), idx)
        self.u_mask = ~bc_local[self.u_dofs] if nf else np.zeros((0, 18), bool)       # constrained dofs get no force

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
        coh = np.array([s.cohesion for s in self.settings])[self.fault]
        tphi = np.tan(np.radians([s.friction_angle for s in self.settings]))[self.fault]
        h = np.maximum(self.h, 1e-300)
        c = face_young / h
        if len(self.pairs):
            # S_f: the sum of the face's stabilisation matrices
            S_f = np.zeros((self.nf_total, 3, 3))
            np.add.at(S_f, self.pairs[:, 0], self.pair_S)
            np.add.at(S_f, self.pairs[:, 1], self.pair_S)
            lam = np.linalg.eigvalsh(S_f[self.face])[:, -1] / np.maximum(self.area, 1e-300)
            c = np.where(lam > 0, np.minimum(c, 0.5 / np.maximum(lam, 1e-300)), c)
        law = ct.FaceLaw(self.area, coh, tphi, c, c)
        k = self.young / h
        kn = np.array([s.penalty_normal for s in self.settings])[self.fault]
        kt = np.array([s.penalty_tangential for s in self.settings])[self.fault]
        return law, ct.FaceLaw(self.area, coh, tphi, np.where(kn > 0, kn, k), np.where(kt > 0, kt, k))

    # -- data exchange ------------------------------------------------------------------------
    def _setup_gather(self):
        ids = np.concatenate(self.mpi.allgather(self.face)) if self.nf_total else np.zeros(0, np.int64)
        self.all_ids = ids.astype(np.int64)
        self.all_g_lm = np.zeros((self.nf_total, 3), np.int64)
        glm = self.mpi.allgather(self.g_lm.astype(np.int64))
        if self.nf_total:
            self.all_g_lm[self.all_ids] = np.concatenate(glm)

    def gather_faces(self, values):
        """Per-owned-face arrays (nf, k) -> (nf_total, k) in serial face order on every rank."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        k = values.shape[1] if values.ndim > 1 else 1
        parts = self.mpi.allgather(values.reshape(self.nf, k))
        out = np.zeros((self.nf_total, k))
        if self.nf_total:
            out[self.all_ids] = np.concatenate(parts)
        return out

    # -- kinematics and tractions -------------------------------------------------------------
    def jumps(self, u_loc):
        """Face-average jump, global (nf,3) and local (nf,3)."""
        g = (u_loc[self.plus_dofs] - u_loc[self.minus_dofs]).mean(axis=1)
        return g, np.einsum("nij,nj->ni", self.R, g)

    def effective(self, t):
        """Effective tractions (Terzaghi): the multiplier is the total traction; friction and opening act on
        t_N + alpha p."""
        te = np.array(t, dtype=float, copy=True)
        te[:, 0] += self.pn
        return te

    def _penalty(self, gl, state=None):
        """Penalty faces' total traction, its derivative and state (zero rows for Lagrange faces). ``state``:
        the branches to take instead of the return map's (stick or open)."""
        pen = ~self.lagrange
        t = np.zeros((self.nf, 3))
        d = np.zeros((self.nf, 3, 3))
        st = np.full(self.nf, ct.STICK)
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
            gl = self.jumps(x_loc)[1]
        t, _, _ = self._penalty(gl, state)
        lag = self.lagrange
        if self.has_lagrange:
            t[lag] = x_loc[self.lm_dofs[lag]]
        return t

    def set_pore_pressure(self, alpha_p):
        """alpha p (Pa, compression positive) at each owned face for the contact laws."""
        self.pn = np.asarray(alpha_p, dtype=float).copy()

    def begin_step(self, x_loc):
        """Record the converged state ``x_loc`` (under the pore pressure it was solved for) as the start of the
        next step."""
        if len(self.pairs):
            self.t_ref_all = self.gather_faces(self.t0)
        gl = self.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl)
        g = np.where(self.lagrange[:, None], self._stabilised(x_loc, gl, t)[0], gl)
        self.start = StepStart(g, t, self.start.state)     # the states are measured from this start
        self.start = StepStart(g, t, self.states(x_loc, exact=True))

    def start_from(self, x_loc, t):
        """Start the faces' laws at the state x_loc from the total tractions ``t`` (owned faces, local frame):
        the initial traction t0 of a geostatic state, or the tractions a checkpoint recorded. A penalty face's
        tangential traction is its history's return map, not a function of its jump; Lagrange faces read
        theirs from their multipliers. Then ``begin_step`` at x_loc (which reads the penalty faces' start only)."""
        self.start = StepStart(self.jumps(x_loc)[1], np.array(t, dtype=float), self.start.state)
        self.begin_step(x_loc)

    def initial_tractions(self, sigma0):
        """Multipliers of the initial state: the prestress of the minus cell projected on the face (local frame;
        the prestress is continuous across a fault in a layered initial state)."""
        tg = np.einsum("nij,nj->ni", sigma0[self.cell], self.normal)
        return np.einsum("nij,nj->ni", self.R, tg)

    # -- states ---------------------------------------------------------------------------------
    def states(self, x_loc, exact=False):
        """Stick/slip/open of every owned face at the iterate x_loc. ``exact``: the branches the residual takes;
        otherwise as reported: a face within round-off (1e-9 E) of a switch counts as closed and stuck."""
        gl = self.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl)
        st = self._penalty(gl)[2]
        gs = self._stabilised(x_loc, gl, t)[0] if self.has_lagrange else gl
        lag = self.lagrange
        if np.any(lag):
            tol = 0.0 if exact else 1e-9 * self.young[lag]
            st[lag] = ct.states(self.law[lag], gs[lag], self.start.g[lag], self.effective(t)[lag], tol)
        return st

    def counts_by_state(self, x_loc):
        st = self.states(x_loc)
        c = self.mpi.allreduce(np.bincount(st, minlength=3), op=MPI.SUM)
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
        dt_all = self.gather_faces(t) - self.t_ref_all
        rs, blocks = stabilization_rows(self.pairs, self.pair_S, self.pos, dt_all, self.all_g_lm)
        return gl + rs / np.maximum(self.area, 1e-300)[:, None], blocks

    def _lagrange_terms(self, x_loc, state=None):
        """Owned Lagrange faces: (indices, states, rows, dr/dg, dr/dt, stabilisation blocks). The law takes the
        stabilised jump; its derivative reaches the neighbours' multipliers through the stabilisation blocks.
        ``state`` (owned faces): the branches to take instead of the iterate's (stick or open)."""
        gl = self.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl)
        gs, sblocks = self._stabilised(x_loc, gl, t)
        idx = np.nonzero(self.lagrange)[0]
        st, r, dg, dt = ct.lagrange_rows(self.law[idx], gs[idx], self.start.g[idx], self.effective(t)[idx],
                                         None if state is None else state[idx])
        # d r / d t_b = (d r / d g_stab) S_ab / A of the row face (dg is dr/dg_stab)
        drdgs = np.zeros((self.nf, 3, 3))
        drdgs[idx] = dg / np.maximum(self.area[idx], 1e-300)[:, None, None]
        blocks = []
        for own, rows, cols, vals in sblocks:
            keep = self.lagrange[own]
            if np.any(keep):
                blocks.append((rows[keep], cols[keep], np.einsum("nij,njk->nik", drdgs[own[keep]], vals[keep])))
        return idx, st, r, dg, dt, blocks

    def residual(self, x_loc, out, state=None):
        """Add the interface terms to the local residual array ``out``; returns the owned faces' states.
        ``state``: the faces' branches to take instead of the iterate's (stick or open)."""
        with logged("pfaultFaultResidual"):
            return self._residual(x_loc, out, state)

    def _residual(self, x_loc, out, state):
        gl = self.jumps(x_loc)[1]
        t = self.tractions(x_loc, gl, state)
        # forces on the displacement dofs from the traction change (the initial traction is in equilibrium
        # with the initial stress): minus side -(A/3) R^T dt, plus side +(A/3) R^T dt
        force = np.einsum("nji,nj->ni", self.R, t - self.t0) * (self.area / 3.0)[:, None]
        fu = self.sign[None, :] * np.tile(force, (1, 6)) * self.u_mask
        out += np.bincount(self.u_dofs.ravel(), weights=fu.ravel(), minlength=len(out))
        out_state = self._penalty(gl, state)[2]
        if self.has_lagrange:
            idx, st, r, _, _, _ = self._lagrange_terms(x_loc, state)
            out_state[idx] = st
            out += np.bincount(self.lm_dofs[idx].ravel(), weights=r.ravel(), minlength=len(out))
        return out_state

    def add_jacobian(self, x_loc, J, state=None, glued=False):
        """Add the interface blocks to J (global indices); returns the owned faces' states. ``state``: the
        faces' branches to take instead of the iterate's (stick or open); ``glued``: every face stuck whatever
        x_loc (the penalty and Lagrange laws' stick branches)."""
        with logged("pfaultFaultJacobian"):
            return self._add_jacobian(x_loc, J, state, glued)

    def _add_jacobian(self, x_loc, J, state, glued):
        gl = self.jumps(x_loc)[1]
        _, d, out_state = self._penalty(gl, state)
        if glued:
            law = self.penalty_law
            d = np.stack([law.c_n, law.c_t, law.c_t], axis=1)[:, :, None] * np.eye(3)[None]
            state = np.full(self.nf, ct.STICK)
        if self.has_lagrange:
            idx, st, _, dg, dt, blocks = self._lagrange_terms(x_loc, state)
            out_state[idx] = st
            self._add_lagrange_blocks(J, idx, dg, dt)
            for rows, cols, vals in blocks:
                J.setValuesRCV(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType), vals.reshape(-1, 9), addv=ADD)
        pen = np.nonzero(~self.lagrange)[0]
        if len(pen):
            self._add_penalty_blocks(J, pen, d[pen])
        return out_state

    def add_glued(self, J):
        """Add the interface blocks of glued faults (every face stuck, no jump) to J: the linear operator of
        the gravity state a geostatic scene starts from."""
        self.add_jacobian(np.zeros(self.n_local), J, glued=True)

    def _add_lagrange_blocks(self, J, idx, dg, dt):
        """Blocks of Lagrange faces ``idx``: forces on the displacement rows, d force/d t = sign A/3 R^T, and the
        constraint rows' dr/du = dr/dg_loc R (1/3) sign and dr/dt."""
        n = len(idx)
        if n == 0:
            return      # (petsc4py's setValuesRCV divides by the number of rows)
        sign = self.sign.reshape(6, 3)[:, 0]
        blk = (sign[None, :, None, None] * (self.area[idx] / 3.0)[:, None, None, None]
               * np.transpose(self.R[idx], (0, 2, 1))[:, None, :, :]).reshape(n, 18, 3)
        J.setValuesRCV(self.g_u[idx], self.g_lm[idx], (blk * self.u_mask[idx][:, :, None]).reshape(n, 54), addv=ADD)
        drdg = np.einsum("nij,njk->nik", dg, self.R[idx]) / 3.0
        blk = (sign[None, None, :, None] * drdg[:, :, None, :]).reshape(n, 3, 18) * self.u_mask[idx][:, None, :]
        J.setValuesRCV(self.g_lm[idx], self.g_u[idx], blk.reshape(n, 54), addv=ADD)
        J.setValuesRCV(self.g_lm[idx], self.g_lm[idx], dt.reshape(n, 9), addv=ADD)

    def _add_penalty_blocks(self, J, pen, d):
        """Blocks of penalty faces ``pen`` with traction derivative d = dt/dg_loc (n,3,3):
        force = A/3 R^T t(g_loc), g_loc = R (1/3) sum sign u."""
        sign = self.sign.reshape(6, 3)[:, 0]
        dfdg = np.einsum("nji,njk,nkl->nil", self.R[pen], d, self.R[pen]) * (self.area[pen] / 9.0)[:, None, None]
        blk = sign[None, :, None, None, None] * sign[None, None, None, :, None] * dfdg[:, None, :, None, :]
        mask = self.u_mask[pen]
        blk = blk.reshape(len(pen), 18, 18) * mask[:, :, None] * mask[:, None, :]
        J.setValuesRCV(self.g_u[pen], self.g_u[pen], blk.reshape(len(pen), 324), addv=ADD)

    def jacobian_varies(self, state):
        """Whether the Jacobian depends on the iterate beyond the faces' states (slipping or penalty faces),
        on all ranks."""
        local = bool(np.any(state == ct.SLIP) or np.any(~self.lagrange))
        return self.mpi.allreduce(local, op=MPI.LOR)

    def insert_pattern(self, J):
        """Insert explicit zeros where the interface blocks go (for exact preallocation)."""
        lag = np.nonzero(self.lagrange)[0]
        n = len(lag)
        if n:
            J.setValuesRCV(self.g_u[lag], self.g_lm[lag], np.zeros((n, 54)), addv=ADD)
            J.setValuesRCV(self.g_lm[lag], self.g_u[lag], np.zeros((n, 54)), addv=ADD)
            J.setValuesRCV(self.g_lm[lag], self.g_lm[lag], np.zeros((n, 9)), addv=ADD)
        pen = np.nonzero(~self.lagrange)[0]
        if len(pen):   # both sides' dofs of a penalty face
            J.setValuesRCV(self.g_u[pen], self.g_u[pen], np.zeros((len(pen), 324)), addv=ADD)

    def stabilization_pattern(self):
        """(rows, cols) global index pairs of the stabilisation blocks in rows this rank owns."""
        return stabilization_pattern(self.pairs, self.pos, self.all_g_lm)

    # -- output -----------------------------------------------------------------------------------
    def face_fields(self, x_loc):
        """Per owned face: traction local (3), jump local (3), traction global (3), slip global (3), state."""
        g, gl = self.jumps(x_loc)
        t = self.tractions(x_loc, gl)
        tg = np.einsum("nji,nj->ni", self.R, t)
        slip_global = g - gl[:, :1] * self.normal
        return t, gl, tg, slip_global, self.states(x_loc)
