"""The equations: F(x) = K u - f(t) + fault terms with Dirichlet rows, and their Jacobian.

The elastic skeleton is given a ``pfault.faults.interface.FaultInterface`` when the scene has faults (``faults``
None otherwise). Without faults F is linear and K its Jacobian; with faults the interface adds the faces'
residual rows and Jacobian blocks, the faces' stick/slip/open states read from each iterate. How the equations
are solved (SNES and KSP set-up, predictor, factor reuse, step cutting) is ``pfault.solver.policy``'s.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Any, Iterator

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..effects import logged
from ..faults import contact as ct
from .setup import rigid_body_modes


def constrained_local(mesh: Any, dofmap: Any) -> np.ndarray:
    """Boolean mask of the local dofs fixed by Dirichlet conditions."""
    mask = mesh.vert_data[:, 0]
    loc = np.zeros(dofmap.n_local, dtype=bool)
    for side in (0, 1):
        sel = dofmap.vert_sides > side
        dofs = dofmap.vertex_dofs(side)[sel]
        bits = (mask[sel, None] >> np.arange(3)) & 1
        loc[dofs[bits == 1]] = True
    return loc


class Equations:
    """Linear elastic skeleton loaded by the pore-pressure change of ``source``, gravity/prestress and
    tractions, with the interface terms of ``faults`` (or None). ``f`` holds the load of the time last set
    (``set_load``); ``J`` the Jacobian last assembled."""

    def __init__(self, mesh: Any, dofmap: Any, assembler: Any, boundaries: list, source: Any, settings: Any,
                 faults: Any = None, contact: Any = None) -> None:
        self.mesh, self.dofmap, self.asm = mesh, dofmap, assembler
        self.dm = mesh.dm
        self.comm = self.dm.getComm()
        self.boundaries, self.source, self.settings = boundaries, source, settings
        self.faults, self.contact = faults, contact
        self._log_residual = PETSc.Log.Event("pfaultResidual")
        self._log_jacobian = PETSc.Log.Event("pfaultJacobian")
        log_assembly = PETSc.Log.Event("pfaultAssembleK")
        self.comm.tompi4py().Barrier()  # assembly_wall times the assembly, not the ranks' arrival (as DOLFINx's)
        log_assembly.begin()
        t0 = time.perf_counter()
        self.K = self._build_operator()
        self.bc_rows = self._constrained_rows()
        with logged("pfaultDisplacementLoad"):
            self.lifts = self._prescribed_displacements()
        self.K.zeroRowsColumns(self.bc_rows, diag=1.0)
        self.assembly_wall = time.perf_counter() - t0
        log_assembly.end()
        self.nullspace = rigid_body_modes(mesh, dofmap, self.dm)
        self.K.setNearNullSpace(self.nullspace)
        self.J = self.K
        if faults is not None:
            self.J = self.K.duplicate(copy=True)
            self.J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
            self.J.setNearNullSpace(self.nullspace)
        self.f = self.dm.createGlobalVec()
        self.static_local = np.zeros(dofmap.n_local)     # loads that do not change in time (tests' body forces)
        self.n_jacobians = 0            # interface Jacobians assembled (a configuration seen before is kept)
        self._jacobian_key = None       # faces' states of the assembled J while it depends on nothing else
        self._states = None             # faces' states imposed on residual and Jacobian (fixed_states)
        self._gravity_norm: float | None = None
        self.surface_loads = []         # boundary loads per surface, scaled by the surface's history
        with logged("pfaultTractionLoad"):
            for i, b in enumerate(boundaries):
                if b.kind in ("traction", "displacement") and any(b.traction):
                    loc = np.zeros(dofmap.n_local)
                    tr = [bb.traction if j == i else (0.0, 0.0, 0.0) for j, bb in enumerate(boundaries)]
                    assembler.traction_load(tr, loc)
                    self.surface_loads.append((b, loc))

    def _build_operator(self) -> Any:
        # Filled as BAIJ (every point carries 3k dofs, so the DM's local-to-global map has block size 3): a cell
        # adds 16 3x3 blocks, each found once, where an AIJ matrix looks up 144 entries one by one. Converted
        # once to AIJ, which every solver takes (GAMG takes no BAIJ). 1M-tet box, 2 ranks: insertion 0.3 s
        # instead of 0.7 s, conversion 0.16 s
        self.dm.setMatType(PETSc.Mat.Type.BAIJ)
        try:
            Kb = self.dm.createMatrix()     # (petsc4py 3.18 has no DMGetMatType: pfault's DMs use AIJ)
        finally:
            self.dm.setMatType(PETSc.Mat.Type.AIJ)
        Kb.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.asm.add_stiffness(Kb, blocked=Kb.getLGMap()[0].getBlockSize() == 3)
        if self.faults is not None:
            self.faults.insert_pattern(Kb)
        Kb.assemble()
        lgmap = Kb.getLGMap()
        K = Kb.convert(PETSc.Mat.Type.AIJ)      # in place; the conversion drops the local-to-global map
        K.setLGMap(*lgmap)
        K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        if self.faults is None:
            return K
        # rebuilt with the stabilisation's pattern and block size 3 (every point carries 3, 6 or 3k dofs: AMG
        # reads the block size from the matrix)
        rows, cols = self.faults.stabilization_pattern()
        K1 = _extend_pattern(K, rows, cols, bs=3)
        K.destroy()
        return K1

    # -- constraints ---------------------------------------------------------------------------
    def _constrained_rows(self) -> np.ndarray:
        loc = constrained_local(self.mesh, self.dofmap).astype(float)
        g = self.to_global(loc, PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        rows = (np.nonzero(g.getArray() > 0.5)[0] + start).astype(PETSc.IntType)
        g.destroy()
        self.bc_local_owned = rows - start
        return rows

    def _prescribed_displacements(self) -> list:
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
            g = self.to_global(loc, PETSc.InsertMode.INSERT_VALUES)
            lift = g.duplicate()
            self.K.mult(g, lift)
            lift.scale(-1.0)
            out.append((b, g, lift))
        return out

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

    # -- loads ---------------------------------------------------------------------------------
    def cell_dp(self, t: float) -> np.ndarray:
        """Pore-pressure change per local cell at time t (Pa; the source's, zero where it is inactive)."""
        if not self.source.active:
            return np.zeros(len(self.mesh.cells))
        return self.source.cell_dp(t)

    def set_load(self, t: float) -> None:
        """The load f(t) and, with faults, the pore pressure their laws see at t."""
        loc = self.static_local.copy()
        for b, fl in self.surface_loads:
            loc += b.scale(t) * fl
        if self.source.active:
            with logged("pfaultPorePressureLoad"):
                self.asm.pore_pressure_load(self.source.cell_dp(t), loc)
        self.to_global(loc, out=self.f)
        for b, g, lift in self.lifts:
            self.f.axpy(b.scale(t), lift)
        arr = self.f.getArray()
        arr[self.bc_local_owned] = 0.0
        for b, g, lift in self.lifts:
            arr[self.bc_local_owned] += b.scale(t) * g.getArray()[self.bc_local_owned]
        if self.faults is not None:
            self.faults.set_pore_pressure(self.face_pore_pressure(t))

    def face_pore_pressure(self, t: float) -> np.ndarray:
        """alpha p at the owned fault faces (Pa): the hydrostatic pressure below the water table at the face
        centroid when the scene starts from the geostatic state, plus the change at time t (minus cell).

        In a geostatic scene p is the absolute pressure, and it is clamped at zero unless
        ``-pfault_contact_suction``: a fault face above the lowered water table is dry. Without the geostatic
        state p is only the change from an unknown initial pressure, and it is used as it is."""
        f = self.faults
        if not self.contact.effective_stress or not f.nf:
            return np.zeros(f.nf)
        s = self.settings
        p = np.zeros(f.nf)
        if s.geostatic:
            z = self.mesh.coords[f.verts][:, :, 2].mean(axis=1)
            p += s.water_density * s.gravity * np.maximum(s.water_table - z, 0.0)
        if self.source.active and t > 0:
            p += self.source.cell_dp(t)[f.cell]
        if s.geostatic and not self.contact.suction:
            p = np.maximum(p, 0.0)
        return self.asm.alpha[f.cell] * p

    def gravity_load(self, out: Any) -> None:
        """The gravity load vector (zero on constrained dofs) into ``out``."""
        grav = np.zeros(self.dofmap.n_local)
        self.asm.gravity_load(self.settings.gravity, grav)
        self.to_global(grav, out=out)
        out.getArray()[self.bc_local_owned] = 0.0

    def gravity_load_norm(self) -> float:
        """|gravity load| of a geostatic scene (0 otherwise), computed once."""
        if self._gravity_norm is None:
            self._gravity_norm = 0.0
            if self.settings.geostatic:
                g = self.create_vec()
                self.gravity_load(g)
                self._gravity_norm = g.norm()
                g.destroy()
        return self._gravity_norm

    # -- geostatic initial state ---------------------------------------------------------------
    def glued_operator(self) -> Any:
        """The operator of the elastic gravity solve: K, with every fault face glued (no jump) while it forms."""
        if self.faults is None:
            return self.K
        A = self.J
        self.K.copy(A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.faults.add_glued(A)
        A.assemble()
        self._jacobian_key = None
        if not self.faults.jacobian_varies(np.full(self.faults.nf, ct.STICK)):
            # the Jacobian of every face stuck: a first step that starts so keeps this factorisation
            self._jacobian_key = np.full(self.faults.nf, ct.STICK)
        return A

    def geostatic_stress(self, u_gravity_local: np.ndarray) -> np.ndarray:
        """The initial stress (cells x 3 x 3, Pa) from the elastic gravity state: its vertical stress (the
        overburden in flat layers, the arching around stiff bodies), horizontal stresses by the K0 rule on
        effective stresses, sigma'_h = K0 sigma'_v, with hydrostatic pore pressure below the water table (K0 =
        -pfault_geostatic_k0, default nu/(1-nu) of each material); no initial shear."""
        s = self.settings
        sig = self.asm.effective_stress(u_gravity_local)
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
        return sigma0

    def cell_total_stress(self, u_local: np.ndarray, dp: np.ndarray, sigma0: np.ndarray | None) -> np.ndarray:
        """Total stress per cell: initial + C:eps(u) - alpha dp I (dp per cell, Pa)."""
        sig = self.asm.effective_stress(u_local)
        if sigma0 is not None:
            sig = sig + sigma0
        return sig - (self.asm.alpha * dp)[:, None, None] * np.eye(3)

    # -- residual and Jacobian -----------------------------------------------------------------
    @contextmanager
    def fixed_states(self, states: np.ndarray) -> Iterator[None]:
        """Residual and Jacobian evaluated with the faces in ``states`` instead of those their laws read from
        the iterate (a step's elastic trial)."""
        self._states = states
        try:
            yield
        finally:
            self._states = None

    def residual(self, snes: Any, x: Any, F: Any) -> None:
        """F(x) (an SNES function callback)."""
        self._log_residual.begin()
        self.K.mult(x, F)
        F.axpy(-1.0, self.f)
        if self.faults is not None:
            out = np.zeros(self.dofmap.n_local)
            self.faults.residual(self.local_array(x), out, self._states)
            g = self.to_global(out)
            F.axpy(1.0, g)
            g.destroy()
        self._log_residual.end()

    def assemble_jacobian(self, x: Any, J: Any) -> np.ndarray | None:
        """K plus the interface blocks at x into J. While every face sticks or is open (no slip, no penalty face)
        the Jacobian depends on the faces' states only: an unchanged configuration leaves J untouched. Returns
        the faces' states of a newly assembled J, None when J was kept (or there are no faults)."""
        if self.faults is None:
            return None      # linear skeleton: K is assembled once
        self._log_jacobian.begin()
        f = self.faults
        x_loc = self.local_array(x)
        state = f.states(x_loc, exact=True) if self._states is None else self._states
        varies = f.jacobian_varies(state)
        key = self._jacobian_key
        same = key is not None and not varies and np.array_equal(key, state)
        if self.comm.tompi4py().allreduce(same, op=MPI.LAND):
            self._log_jacobian.end()
            return None
        self.K.copy(J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        f.add_jacobian(x_loc, J, self._states)
        J.assemble()
        self._jacobian_key = None if varies else state
        self.n_jacobians += 1
        self._log_jacobian.end()
        return state

    def destroy(self) -> None:
        for obj in {id(o): o for o in (self.K, self.J, self.f, self.nullspace)}.values():
            obj.destroy()
        for _, g, lift in self.lifts:
            g.destroy()
            lift.destroy()


def _extend_pattern(K0: Any, rows: np.ndarray, cols: np.ndarray, bs: int = 1) -> Any:
    """A new AIJ matrix (block size bs) with K0's values and pattern plus explicit zeros at (rows, cols) (owned
    rows)."""
    rstart, rend = K0.getOwnershipRange()
    indptr, indices, values = K0.getValuesCSR()
    nrows = rend - rstart
    rows = np.asarray(rows, np.int64) - rstart
    if len(rows) and (rows.min() < 0 or rows.max() >= nrows):
        raise RuntimeError("stabilisation rows must be owned")
    ncols = K0.getSize()[1]
    # K0's rows are sorted and without repeats (an assembled AIJ matrix), so its keys row * ncols + col are
    # sorted: the new entries are placed by binary search instead of sorting all entries again (paper-size
    # calibrated Queretaro, with the BAIJ insertion: the operator's build 1.0-1.1 s instead of 1.6-2.3 s)
    key = np.repeat(np.arange(nrows, dtype=np.int64), np.diff(indptr)) * ncols + indices
    extra = np.unique(rows * ncols + np.asarray(cols, np.int64))
    pos = np.searchsorted(key, extra)
    found = pos < len(key)
    found[found] = key[pos[found]] == extra[found]
    extra, pos = extra[~found], pos[~found]
    c_u = np.insert(indices, pos, (extra % ncols).astype(indices.dtype)).astype(PETSc.IntType)
    vals = np.insert(values, pos, 0.0)
    counts = np.diff(indptr) + np.bincount(extra // ncols, minlength=nrows)
    ptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
    K = PETSc.Mat().createAIJ(size=K0.getSizes(), bsize=bs, csr=(ptr, c_u, vals), comm=K0.getComm())
    K.setLGMap(*K0.getLGMap())
    K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    K.assemble()
    return K
