"""Fault interface terms on the distributed mesh: Lagrange-multiplier contact with Mohr-Coulomb
friction (stick/slip/open active set, algebraic stabilisation) or penalty contact.

Every fault face is handled by the rank that owns its minus cell; the face's vertices, with both
sides' displacement dofs, are in that cell's closure, so the interface element is local. Only the
stabilisation couples neighbouring faces, which may sit on other ranks: their multipliers are
gathered on every rank (the fault is a surface: O(faces) data).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..mesh.serial import TET_FACES
from ..physics import contact as ct
from ..physics import elasticity as el


@dataclass(frozen=True)
class FaultSettings:
    name: str
    cohesion: float
    friction_angle: float          # degrees
    method: str                    # lagrange | penalty
    stabilization: bool
    penalty_normal: float          # Pa/m (0: automatic from the adjacent cells)
    penalty_tangential: float


# ---------------------------------------------------------------------------------------------
# serial preprocessing (rank 0)

def stabilization_pairs(serial, split, materials, scale=1.0):
    """Pairs of fault faces sharing an edge and their stabilisation matrices (local frame).

    Following Franceschini, Castelletto, White & Tchelepi (CMAME 2020): for the two faces f0, f1 of a
    fault edge, S = R (K_-^-1 + K_+^-1) R^T * areafac, with K_+- a diagonal stiffness estimate of the
    edge nodes on each side (sum over the two faces' adjacent cells of
    E/((1+nu)(1-2nu)) 2/9 (2-3nu) V/box_j^2) and areafac = sum over the edge nodes of the products
    of the faces' nodal areas. No user coefficient.
    """
    faces = split.faces
    nf = len(faces)
    if nf == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3, 3))
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(nf), 3)
    e = np.sort(edges, axis=1)
    key = e[:, 0] * len(serial.points) + e[:, 1]
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = ks[1:] == ks[:-1]
    counts = np.bincount(np.unique(ks, return_inverse=True)[1])
    first = np.nonzero(same)[0]
    # keep edges shared by exactly two faces of the same fault
    uniq, inv = np.unique(ks, return_inverse=True)
    two = counts[inv[first]] == 2
    f0 = owner[order[first[two]]]
    f1 = owner[order[first[two] + 1]]
    keep = split.fault_id[f0] == split.fault_id[f1]
    f0, f1 = f0[keep], f1[keep]
    young = np.array([m.young_modulus for m in materials])[serial.cell_material]
    nu = np.array([m.poisson_ratio for m in materials])[serial.cell_material]
    x = serial.points[serial.tets]
    vol = np.abs(el.tet_geometry(x)[1])
    box = x.max(axis=1) - x.min(axis=1)
    kdiag = (scale * young / ((1 + nu) * (1 - 2 * nu)) * 2.0 / 9.0 * (2 - 3 * nu) * vol)[:, None] / box ** 2
    k_minus = kdiag[split.minus_cell[f0]] + kdiag[split.minus_cell[f1]]
    k_plus = kdiag[split.plus_cell[f0]] + kdiag[split.plus_cell[f1]]
    inv_k = 1.0 / k_minus + 1.0 / k_plus                                   # (np, 3) diagonal, global axes
    n = split.normal[f0] * split.area[f0, None] + split.normal[f1] * split.area[f1, None]
    R = ct.local_frames(n)
    S = np.einsum("nij,nj,nkj->nik", R, inv_k, R)
    areafac = 2.0 * (split.area[f0] / 3.0) * (split.area[f1] / 3.0)
    return np.column_stack([f0, f1]), S * areafac[:, None, None]


# ---------------------------------------------------------------------------------------------

class FaultSystem:
    """Interface terms of all faults for the faces this rank owns."""

    def __init__(self, mesh, dofmap, settings, fault_id, pairs, pair_S, materials, bc_local, lgmap):
        self.mesh, self.dofmap = mesh, dofmap
        self.settings = settings
        comm = mesh.dm.getComm()
        self.mpi = comm.tompi4py()
        self.nf_total = len(fault_id)
        cells, lfaces = np.nonzero(mesh.cell_fault_face >= 0)
        fid = mesh.cell_fault_face[cells, lfaces]
        order = np.argsort(fid)
        self.face = fid[order]
        self.cell, self.lface = cells[order], lfaces[order]
        nf = len(self.face)
        self.nf = nf
        self.fault = fault_id[self.face]
        verts = mesh.cells[self.cell[:, None], TET_FACES[self.lface]]
        self.verts = verts
        x = mesh.coords[verts]
        an = el.triangle_area_normal(x)            # outward normal of the minus cell = minus -> plus
        self.area = np.linalg.norm(an, axis=1)
        self.normal = an / np.maximum(self.area, 1e-300)[:, None]
        self.R = ct.local_frames(self.normal) if nf else np.zeros((0, 3, 3))
        cd = dofmap.cell_dofs.reshape(-1, 4, 3)
        self.minus_dofs = cd[self.cell[:, None], TET_FACES[self.lface]]               # (nf,3,3)
        self.plus_dofs = dofmap.vertex_dofs(1)[verts]                                  # (nf,3,3)
        # slot of each face in its cell's multiplier block: faces of a cell in local-face order
        slot = np.zeros(nf, np.int64)
        if nf:
            before = (mesh.cell_fault_face[self.cell] >= 0) & (np.arange(4)[None, :] < self.lface[:, None])
            slot = before.sum(axis=1)
        is_lag = np.array([st.method == "lagrange" for st in settings])[self.fault] if nf else np.zeros(0, bool)
        self.lm_dofs = np.where(is_lag[:, None], dofmap.cell_offset[self.cell][:, None] + 3 * slot[:, None]
                                + np.arange(3), -1)
        if nf:
            assert np.all(dofmap.cell_offset[self.cell[is_lag]] >= 0)
        self.u_dofs = np.concatenate([self.minus_dofs.reshape(nf, 9), self.plus_dofs.reshape(nf, 9)], axis=1)
        self.sign = np.concatenate([-np.ones(9), np.ones(9)])                         # jump = plus - minus
        self.lgmap = lgmap
        self.g_u = lgmap.apply(self.u_dofs.ravel().astype(PETSc.IntType)).reshape(nf, 18) if nf else \
            np.zeros((0, 18), PETSc.IntType)
        self.g_lm = lgmap.apply(self.lm_dofs.ravel().astype(PETSc.IntType)).reshape(nf, 3) if nf else \
            np.zeros((0, 3), PETSc.IntType)
        self.u_mask = ~bc_local[self.u_dofs] if nf else np.zeros((0, 18), bool)        # constrained dofs get no fault force
        # friction parameters per face
        coh = np.array([s.cohesion for s in settings])
        tphi = np.tan(np.radians([s.friction_angle for s in settings]))
        self.cohesion = coh[self.fault]
        self.tan_phi = tphi[self.fault]
        self.lagrange = np.array([s.method == "lagrange" for s in settings])[self.fault]
        self.has_lagrange = any(s.method == "lagrange" for s in settings)
        # characteristic sizes for tolerances and penalty stiffness
        h = np.sqrt(self.area)
        young = np.array([m.young_modulus for m in materials])[mesh.cell_material[self.cell]]
        self.h = h
        self.young = young
        kauto = young / np.maximum(h, 1e-300)
        kn = np.array([s.penalty_normal for s in settings])[self.fault]
        kt = np.array([s.penalty_tangential for s in settings])[self.fault]
        self.kn = np.where(kn > 0, kn, kauto)
        self.kt = np.where(kt > 0, kt, kauto)
        self.slide_tol = 1e-10 * h
        self.slip_reg = np.zeros(nf)
        self.c_slip = None                  # augmented slip direction stiffness (Pa/m) or None
        # state
        self.state = np.full(nf, ct.STICK)
        self.t0 = np.zeros((nf, 3))         # initial (prestress) traction, local; loads nothing
        self.pn = np.zeros(nf)              # alpha p at the face: effective traction = t + (pn, 0, 0)
        self.g_prev = np.zeros((nf, 3))     # local jump at the start of the step
        self.t_prev = np.zeros((nf, 3))     # local traction at the start of the step
        # the faces' multipliers in serial order on every rank (stabilisation)
        self._setup_gather()
        stab = np.array([s.stabilization for s in settings])
        keep = stab[fault_id[pairs[:, 0]]] & np.array([s.method == "lagrange" for s in settings])[fault_id[pairs[:, 0]]] \
            if len(pairs) else np.zeros(0, bool)
        self.pairs, self.pair_S = pairs[keep], pair_S[keep]
        self.state_all = np.full(self.nf_total, ct.STICK)
        self.t_prev_all = np.zeros((self.nf_total, 3))

    # -- data exchange ------------------------------------------------------------------------
    def _setup_gather(self):
        counts = self.mpi.allgather(self.nf)
        self.counts = counts
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

    # -- kinematics ---------------------------------------------------------------------------
    def jumps(self, u_loc):
        """Face-average jump, global (nf,3) and local (nf,3)."""
        g = (u_loc[self.plus_dofs] - u_loc[self.minus_dofs]).mean(axis=1)
        return g, np.einsum("nij,nj->ni", self.R, g)

    def tractions(self, x_loc):
        return x_loc[self.lm_dofs] if self.nf else np.zeros((0, 3))

    def effective(self, t, idx=None):
        """Effective tractions (Terzaghi) of all owned faces, or of faces ``idx``: the multiplier is the
        total traction; friction and opening act on t_N + alpha p."""
        te = np.array(t, dtype=float, copy=True)
        te[:, 0] += self.pn if idx is None else self.pn[idx]
        return te

    def _c_slip(self, idx):
        return None if self.c_slip is None else self.c_slip[idx]

    def _state_args(self, idx, gl):
        """Extra arguments of contact.update_states for faces idx (augmented slip law)."""
        if self.c_slip is None:
            return {"slip_to_stick": not np.any(self.slip_reg > 0)}
        # the reversal test measures the backward slip on the face's own stiffness scale E/h, whatever the
        # augmentation c of the slip direction
        return {"dg_t": gl[idx, 1:] - self.g_prev[idx, 1:], "c_aug": self.kt[idx]}

    def set_pore_pressure(self, alpha_p):
        """alpha p (Pa, compression positive) at each owned face for the contact laws."""
        self.pn = np.asarray(alpha_p, dtype=float).copy()

    def begin_step(self, x_loc, carry=None):
        """Record the converged state at the start of a step; slipping faces restart from stick, except those
        in ``carry`` (owned faces still sliding, with a predicted slip increment), which stay slipping."""
        _, gl = self.jumps(x_loc)
        t_new = np.zeros((self.nf, 3))
        if self.has_lagrange:
            t_new[self.lagrange] = self.tractions(x_loc)[self.lagrange]
        pen = ~self.lagrange
        if np.any(pen):
            tp, _, _ = self._penalty(gl)
            t_new[pen] = tp[pen]
        self.g_prev = gl
        self.t_prev = t_new
        carry = np.zeros(self.nf, bool) if carry is None else np.asarray(carry, bool)
        self.state = np.where((self.state == ct.SLIP) & ~carry, ct.STICK, self.state)
        self.last_change = (np.zeros(0, np.int64), np.zeros(0, np.int64))
        self.visited = (1 << self.state).astype(np.int64)   # states each face has held in this step
        self.banned = np.zeros(self.nf, np.int64)            # states a face may not re-enter (it chattered)
        self._sync_state()
        self.t_prev_all = self.gather_faces(self.t_prev)

    def initial_tractions(self, sigma0):
        """Multipliers of the initial state: the prestress of the two adjacent cells, projected on the faces
        (local frame). ``sigma0`` is per local cell (nc,3,3); the plus cell's stress is not local, so the
        minus cell's is used (the prestress is continuous across a fault in a layered initial state)."""
        s = sigma0[self.cell]
        tg = np.einsum("nij,nj->ni", s, self.normal)
        return np.einsum("nij,nj->ni", self.R, tg)

    def insert_pattern(self, J):
        """Insert explicit zeros where the interface blocks go (for exact preallocation)."""
        ADD = PETSc.InsertMode.ADD_VALUES
        lag = np.nonzero(self.lagrange)[0]
        if len(lag):
            J.setValuesRCV(self.g_u[lag], self.g_lm[lag], np.zeros((len(lag), 54)), addv=ADD)
            J.setValuesRCV(self.g_lm[lag], self.g_u[lag], np.zeros((len(lag), 54)), addv=ADD)
            J.setValuesRCV(self.g_lm[lag], self.g_lm[lag], np.zeros((len(lag), 9)), addv=ADD)
        if self.nf:   # both sides' dofs of a face: penalty blocks, and the augmented preconditioner
            J.setValuesRCV(self.g_u, self.g_u, np.zeros((self.nf, 324)), addv=ADD)

    def add_augmentation(self, P):
        """Add gamma B^T W B to the displacement block of the preconditioning matrix P (augmented Lagrangian):
        the jump of every closed face is penalised with gamma = A E/h in its constrained directions (all three
        when stuck, the normal one when slipping). It makes the displacement block nonsingular where a fault
        cuts a body loose, so a Schur-complement fieldsplit applies; the Jacobian itself is unchanged."""
        lag = np.nonzero(self.lagrange & (self.state != ct.OPEN))[0]
        if not len(lag):
            return
        w = np.zeros((len(lag), 3))
        w[:, 0] = 1.0
        w[self.state[lag] == ct.STICK, 1:] = 1.0
        gamma = self.area[lag] * self.young[lag] / self.h[lag]
        # face-average jump in the local frame: g_loc = R (1/3) sum sign_b u_b
        RtWR = np.einsum("nji,nj,njk->nik", self.R[lag], w, self.R[lag]) * (gamma / 9.0)[:, None, None]
        sign = self.sign.reshape(6, 3)[:, 0]
        blk = sign[None, :, None, None, None] * sign[None, None, None, :, None] * RtWR[:, None, :, None, :]
        mask = self.u_mask[lag]
        blk = blk.reshape(len(lag), 18, 18) * mask[:, :, None] * mask[:, None, :]
        P.setValuesRCV(self.g_u[lag], self.g_u[lag], blk.reshape(len(lag), 324).copy(),
                       addv=PETSc.InsertMode.ADD_VALUES)

    def stabilization_pattern(self):
        """(rows, cols) global index pairs of the stabilisation blocks in rows this rank owns."""
        if len(self.pairs) == 0 or not self.nf:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        pos = np.full(self.nf_total, -1)
        pos[self.face] = np.arange(self.nf)
        rows, cols = [], []
        for a, b in ((0, 1), (1, 0)):
            fa, fb = self.pairs[:, a], self.pairs[:, b]
            mine = pos[fa] >= 0
            for f in (fa[mine], fb[mine]):
                r = np.repeat(self.all_g_lm[fa[mine]], 3, axis=1)
                c = np.tile(self.all_g_lm[f], (1, 3))
                rows.append(r.ravel())
                cols.append(c.ravel())
        return np.concatenate(rows), np.concatenate(cols)

    def _sync_state(self):
        self.state_all = self.gather_faces(self.state.astype(float)).ravel().astype(np.int64)

    # -- residual and Jacobian ----------------------------------------------------------------
    def _penalty(self, gl):
        pen = ~self.lagrange
        t = np.zeros((self.nf, 3))
        d = np.zeros((self.nf, 3, 3))
        st = self.state.copy()
        if np.any(pen):
            # the penalty law acts on the effective traction; the faces receive the total one
            t[pen], d[pen], st[pen] = ct.penalty_traction(gl[pen], self.g_prev[pen], self.t_prev[pen], self.kn[pen],
                                                          self.kt[pen], self.cohesion[pen], self.tan_phi[pen],
                                                          self.t0[pen, 0] + self.pn[pen])
            t[pen, 0] -= self.pn[pen]
        return t, d, st

    def _stab_rows(self, t_all):
        """Stabilisation contributions to the rows of owned faces: r (nf,3), and matrix blocks."""
        if len(self.pairs) == 0 or not self.nf:
            return np.zeros((self.nf, 3)), []
        pos = np.full(self.nf_total, -1)
        pos[self.face] = np.arange(self.nf)
        r = np.zeros((self.nf, 3))
        blocks = []
        st = self.state_all
        ncomp = np.array([3, 1, 0])  # stick: all, slip: normal, open: none
        dt_all = t_all - self.t_prev_all
        for a, b in ((0, 1), (1, 0)):
            fa, fb = self.pairs[:, a], self.pairs[:, b]
            mine = pos[fa] >= 0
            if not np.any(mine):
                continue
            fa, fb, S = fa[mine], fb[mine], self.pair_S[mine]
            na, nb = ncomp[st[fa]], ncomp[st[fb]]
            rowmask = np.arange(3)[None, :] < na[:, None]
            colmask = np.arange(3)[None, :] < nb[:, None]
            colmask_a = np.arange(3)[None, :] < na[:, None]
            Saa = -S * rowmask[:, :, None] * colmask_a[:, None, :]
            Sab = S * rowmask[:, :, None] * colmask[:, None, :]
            # the stabilisation acts on the traction increments of the step: a traction field that
            # varies smoothly along the fault (geostatic gradients) is not perturbed by it
            contrib = np.einsum("nij,nj->ni", Saa, dt_all[fa]) + np.einsum("nij,nj->ni", Sab, dt_all[fb])
            np.add.at(r, pos[fa], contrib)
            blocks.append((self.all_g_lm[fa], self.all_g_lm[fa], Saa))
            blocks.append((self.all_g_lm[fa], self.all_g_lm[fb], Sab))
        return r, blocks

    def residual(self, x_loc, t_all, out):
        """Add the interface terms to the local residual array ``out``."""
        if self.nf == 0 and len(self.pairs) == 0:
            return
        g, gl = self.jumps(x_loc)
        t = np.zeros((self.nf, 3))
        lag = self.lagrange
        if self.has_lagrange:
            t[lag] = self.tractions(x_loc)[lag]
        tp, _, _ = self._penalty(gl)
        t = np.where(lag[:, None], t, tp)
        # forces on the displacement dofs from the traction change (the initial traction is in equilibrium
        # with the initial stress): minus side -(A/3) R^T dt, plus side +(A/3) R^T dt
        force = np.einsum("nji,nj->ni", self.R, t - self.t0) * (self.area / 3.0)[:, None]     # global, per vertex
        fu = self.sign[None, :] * np.tile(force, (1, 6)) * self.u_mask
        out += np.bincount(self.u_dofs.ravel(), weights=fu.ravel(), minlength=len(out))
        if self.has_lagrange and np.any(lag):
            r, _, _ = ct.lagrange_rows(self.state[lag], self.area[lag], gl[lag], self.g_prev[lag],
                                       self.effective(t[lag], lag),
                                       self.cohesion[lag], self.tan_phi[lag], self.slide_tol[lag],
                                       self.slip_reg[lag], self._c_slip(lag))
            rs, _ = self._stab_rows(t_all)
            rr = np.zeros((self.nf, 3))
            rr[lag] = r
            rr += rs
            out += np.bincount(self.lm_dofs[lag].ravel(), weights=rr[lag].ravel(), minlength=len(out))

    def add_jacobian(self, x_loc, t_all, J):
        """Insert the interface blocks into J (global indices, ADD)."""
        ADD = PETSc.InsertMode.ADD_VALUES
        g, gl = self.jumps(x_loc)
        lag = self.lagrange
        nf = self.nf
        # d(force)/dt for Lagrange faces; d(force)/dg for penalty faces
        sign = self.sign.reshape(6, 3)[:, 0]
        if self.has_lagrange and np.any(lag):
            idx = np.nonzero(lag)[0]
            t = self.tractions(x_loc)[idx]
            # rows u (18), cols lm (3): sign * A/3 R^T
            blk = (sign[None, :, None, None] * (self.area[idx] / 3.0)[:, None, None, None]
                   * np.transpose(self.R[idx], (0, 2, 1))[:, None, :, :])                    # (n,6,3,3)
            blk = blk.reshape(len(idx), 18, 3) * self.u_mask[idx][:, :, None]
            J.setValuesRCV(self.g_u[idx], self.g_lm[idx], blk.reshape(len(idx), 54).copy(), addv=ADD)
            r, dg, dt = ct.lagrange_rows(self.state[idx], self.area[idx], gl[idx], self.g_prev[idx],
                                         self.effective(t, idx),
                                         self.cohesion[idx], self.tan_phi[idx], self.slide_tol[idx],
                                         self.slip_reg[idx], self._c_slip(idx))
            # d r / d u = dr/dg_loc R (1/3) sign
            drdg = np.einsum("nij,njk->nik", dg, self.R[idx]) / 3.0                           # (n,3,3)
            blk = sign[None, None, :, None] * drdg[:, :, None, :]                              # (n,3,6,3)
            blk = blk.reshape(len(idx), 3, 18) * self.u_mask[idx][:, None, :]
            J.setValuesRCV(self.g_lm[idx], self.g_u[idx], blk.reshape(len(idx), 54).copy(), addv=ADD)
            J.setValuesRCV(self.g_lm[idx], self.g_lm[idx], dt.reshape(len(idx), 9).copy(), addv=ADD)
            _, blocks = self._stab_rows(t_all)
            for rows, cols, vals in blocks:
                J.setValuesRCV(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType),
                               vals.reshape(len(vals), 9).copy(), addv=ADD)
        pen = ~lag
        if np.any(pen):
            idx = np.nonzero(pen)[0]
            _, d, _ = self._penalty(gl)
            # force_global = A/3 R^T t(g_loc), g_loc = R (1/3) sum sign u -> d force / d u
            dfdg = np.einsum("nji,njk,nkl->nil", self.R[idx], d[idx], self.R[idx]) * (self.area[idx] / 9.0)[:, None, None]
            blk = sign[None, :, None, None, None] * sign[None, None, None, :, None] * dfdg[:, None, :, None, :]
            blk = blk.reshape(len(idx), 18, 18) * self.u_mask[idx][:, :, None] * self.u_mask[idx][:, None, :]
            J.setValuesRCV(self.g_u[idx], self.g_u[idx], blk.reshape(len(idx), 324).copy(), addv=ADD)

    # -- active set ---------------------------------------------------------------------------
    @property
    def frozen(self):
        return self.banned != 0

    def save_state(self):
        self._saved = (self.state.copy(), self.visited.copy(), self.banned.copy())

    def restore_state(self):
        self.state, self.visited, self.banned = (a.copy() for a in self._saved)
        self._sync_state()

    def update_active_set(self, x_loc, traction_tol, opening_tol, slip_tol_ratio, fraction=1.0):
        """New stick/slip/open states of Lagrange faces; returns the changed area (all ranks).

        Rules in pfault.physics.contact.update_states. A face returning to a state it already held in this
        step is frozen in it (anti-chatter). With fraction < 1 only that share of the faces asking for a
        change (at least one: those asking most strongly, ranked over all ranks) changes: the bounded
        update after a configuration that Newton could not solve."""
        lag = np.nonzero(self.lagrange)[0]
        opening_tol = self._opening_tol(opening_tol)[lag]
        old = self.state[lag]
        _, gl = self.jumps(x_loc)
        t = self.effective(self.tractions(x_loc))
        new = ct.update_states(old, t[lag], gl[lag], self.cohesion[lag], self.tan_phi[lag], traction_tol,
                               opening_tol, slip_tol_ratio, **self._state_args(lag, gl))
        # a face kept closed by the anti-chatter rule while in tension cannot carry shear (tau_L = 0): it slips
        new = np.where(self._kept_closed(lag, old, new), ct.SLIP, new)
        new = np.where((self.banned[lag] >> new) & 1 == 1, old, new)
        if fraction < 1.0:
            v = ct.violation(old, new, t[lag], gl[lag], self.cohesion[lag], self.tan_phi[lag], traction_tol,
                             opening_tol)
            allv = np.concatenate(self.mpi.allgather(v[v > 0]))
            keep = max(1, int(np.floor(fraction * len(allv))))
            if len(allv) > keep:
                threshold = np.sort(allv)[::-1][keep - 1]
                new = np.where(v >= threshold, new, old)
        # anti-chatter: a face returning to a state it held earlier in the step may not go back to the one it
        # leaves (it may still move on to the third state)
        self.last_change = (lag[new != old], new[new != old])
        back = (new != old) & (((self.visited[lag] >> new) & 1) == 1)
        self.banned[lag] |= np.where(back, 1 << old, 0)
        self.visited[lag] |= 1 << new
        self.last_transitions = self.mpi.allreduce(ct.transition_counts(old, new), op=MPI.SUM)
        changed = float(self.area[lag][new != old].sum())
        st = self.state.copy()
        st[lag] = new
        self.state = st
        self._sync_state()
        return self.mpi.allreduce(changed, op=MPI.SUM)

    def _kept_closed(self, idx, old, new):
        """Faces idx that ask to open (new) but are banned from opening while closed (old): the anti-chatter
        rule keeps them closed."""
        return (new == ct.OPEN) & (((self.banned[idx] >> ct.OPEN) & 1) == 1) & (old != ct.OPEN)

    def _opening_tol(self, tol):
        """Per-face interpenetration tolerance: the user's value, or 1e-6 of the face size."""
        return np.full(self.nf, tol) if tol >= 0 else 1e-6 * self.h

    def frozen_violations(self, x_loc, traction_tol, opening_tol, slip_tol_ratio):
        """Faces kept in a state by the anti-chatter rule that the contact conditions reject, and the largest
        such violation relative to the fault's median normal traction (tension on a closed face, or the shear
        excess over the Coulomb limit). Returns (count, relative violation), the same on all ranks."""
        faces, excess, t_ref = self._frozen_violating(x_loc, traction_tol, opening_tol, slip_tol_ratio)
        worst = float(np.max(excess)) / t_ref if len(excess) else 0.0
        return int(self.mpi.allreduce(len(faces), op=MPI.SUM)), float(self.mpi.allreduce(worst, op=MPI.MAX))

    def _frozen_violating(self, x_loc, traction_tol, opening_tol, slip_tol_ratio):
        """(owned faces, their violation in Pa, the fault's median normal traction) of the frozen faces the
        contact conditions reject (see frozen_violations)."""
        t = self.effective(self.tractions(x_loc))
        t_all = t[self.lagrange] if self.has_lagrange else np.zeros((0, 3))
        tn_all = np.concatenate(self.mpi.allgather(np.abs(t_all[:, 0])))
        t_ref = max(float(np.median(tn_all)) if len(tn_all) else 0.0, traction_tol)
        lag = np.nonzero(self.lagrange & self.frozen)[0] if hasattr(self, "banned") else np.zeros(0, np.int64)
        if not len(lag):
            return lag, np.zeros(0), t_ref
        opening_tol = self._opening_tol(opening_tol)[lag]
        _, gl = self.jumps(x_loc)
        new = ct.update_states(self.state[lag], t[lag], gl[lag], self.cohesion[lag], self.tan_phi[lag],
                               traction_tol, opening_tol, slip_tol_ratio, **self._state_args(lag, gl))
        kept_closed = self._kept_closed(lag, self.state[lag], new)
        viol = (((new != self.state[lag]) & (((self.banned[lag] >> new) & 1) == 1))
                | (kept_closed & (t[lag][:, 0] > traction_tol)))
        tt = t[lag][viol]
        tau = ct.coulomb_limit(tt[:, 0], self.cohesion[lag][viol], self.tan_phi[lag][viol])
        excess = np.maximum(tt[:, 0], np.linalg.norm(tt[:, 1:], axis=1) - tau)
        return lag[viol], excess, t_ref

    def release_frozen(self, x_loc, traction_tol, opening_tol, slip_tol_ratio, chatter_tol):
        """Lift the anti-chatter bans of the frozen faces that violate the contact conditions by more than
        chatter_tol of the median normal traction: they may change state again, and their history in this
        step restarts from their present state (also in the saved state, as ban_last_change does for a ban).
        Returns how many faces were released (all ranks)."""
        faces, excess, t_ref = self._frozen_violating(x_loc, traction_tol, opening_tol, slip_tol_ratio)
        faces = faces[excess > chatter_tol * t_ref]
        self.banned[faces] = 0
        self.visited[faces] = 1 << self.state[faces]
        if hasattr(self, "_saved"):
            self._saved[1][faces] = 1 << self._saved[0][faces]
            self._saved[2][faces] = 0
        return int(self.mpi.allreduce(len(faces), op=MPI.SUM))

    def ban_last_change(self):
        """Forbid the changes of the last update (a single face whose change Newton could not solve even
        alone); returns how many faces were banned (all ranks)."""
        faces, states = getattr(self, "last_change", (np.zeros(0, np.int64), np.zeros(0, np.int64)))
        self.banned[faces] |= 1 << states
        if hasattr(self, "_saved"):
            self._saved[2][faces] |= 1 << states
        return int(self.mpi.allreduce(len(faces), op=MPI.SUM))

    def frozen_count(self):
        n = int(np.count_nonzero(self.frozen)) if hasattr(self, "banned") else 0
        return int(self.mpi.allreduce(n, op=MPI.SUM))

    def counts_by_state(self, x_loc):
        st = self.current_states(x_loc)
        c = np.bincount(st, minlength=3) if len(st) else np.zeros(3, np.int64)
        c = self.mpi.allreduce(c, op=MPI.SUM)
        return {name: int(c[i]) for i, name in enumerate(ct.STATE_NAMES)}

    def current_states(self, x_loc):
        st = self.state.copy()
        pen = ~self.lagrange
        if np.any(pen):
            _, gl = self.jumps(x_loc)
            _, _, s = self._penalty(gl)
            st[pen] = s[pen]
        return st

    def face_fields(self, x_loc):
        """Per owned face: traction local (3), jump local (3), traction global (3), slip global (3), state."""
        g, gl = self.jumps(x_loc)
        t = np.zeros((self.nf, 3))
        if self.has_lagrange:
            t[self.lagrange] = self.tractions(x_loc)[self.lagrange]
        tp, _, _ = self._penalty(gl)
        t = np.where(self.lagrange[:, None], t, tp)
        tg = np.einsum("nji,nj->ni", self.R, t)
        slip_global = g - gl[:, :1] * self.normal
        return t, gl, tg, slip_global, self.current_states(x_loc)
