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

from ..errors import run_on_root
from ..faults import contact as ct
from ..physics import elasticity as el
from ..physics import geostatic as gs
from .loads import Loads
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
    tractions (``loads``, a pfault.solver.loads.Loads), with the interface terms of ``faults`` (or None). ``J``
    holds the Jacobian last assembled."""

    def __init__(self, mesh: Any, dofmap: Any, assembler: Any, boundaries: list, source: Any, settings: Any,
                 faults: Any = None, contact: Any = None) -> None:
        self.mesh, self.dofmap, self.asm = mesh, dofmap, assembler
        self.dm = mesh.dm
        self.comm = self.dm.getComm()
        self.settings, self.faults = settings, faults
        self._log_residual = PETSc.Log.Event("pfaultResidual")
        self._log_jacobian = PETSc.Log.Event("pfaultJacobian")
        log_assembly = PETSc.Log.Event("pfaultAssembleK")
        self.comm.tompi4py().Barrier()  # assembly_wall times the assembly, not the ranks' arrival (as DOLFINx's)
        log_assembly.begin()
        t0 = time.perf_counter()
        self.K = self._build_operator()
        self.bc_rows = self._constrained_rows()
        # the lifts of prescribed displacements take K before its constrained rows and columns are zeroed
        self.loads = Loads(self, boundaries, source, settings, contact)
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
        self.n_jacobians = 0            # interface Jacobians assembled (a configuration seen before is kept)
        self._jacobian_key: np.ndarray | None = None    # faces' states of J while it depends on nothing else
        self._states: np.ndarray | None = None  # faces' states imposed on residual and Jacobian (fixed_states)

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
        blocked = Kb.getLGMap()[0].getBlockSize() == 3
        self.asm.add_stiffness(Kb, blocked=blocked)
        if self.faults is not None:
            self.faults.add_stiffness(Kb, blocked)      # the condensed face bubbles
            self.faults.faces.insert_pattern(Kb)
        Kb.assemble()
        lgmap = Kb.getLGMap()
        K = Kb.convert(PETSc.Mat.Type.AIJ)      # in place; the conversion drops the local-to-global map
        K.setLGMap(*lgmap)
        K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        if self.faults is None:
            return K
        # rebuilt with the pattern of the bubbles' blocks (beyond the cells' closures: a face's row reaches the
        # plus cell's fourth vertex, a cell's rows the multipliers of its faces, a face's row those of the faces
        # sharing a cell) and block size 3 (every point carries 3, 6 or 3k dofs: AMG reads the block size from the
        # matrix)
        rows, cols = _to_owners(K, *self.faults.pattern())
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

    # -- geostatic initial state ---------------------------------------------------------------
    def glued_operator(self) -> Any:
        """The operator of the elastic gravity solve: K, with every fault face glued (no jump) while it forms."""
        if self.faults is None:
            return self.K
        A = self.J
        self.K.copy(A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.faults.add_glued(A, self.dofmap.n_local)
        A.assemble()
        self._jacobian_key = None
        if not self.faults.jacobian_varies(np.full(self.faults.faces.nf, ct.STICK)):
            # the Jacobian of every face stuck: a first step that starts so keeps this factorisation
            self._jacobian_key = np.full(self.faults.faces.nf, ct.STICK)
        return A

    def geostatic_stress(self, u_gravity_local: np.ndarray) -> np.ndarray:
        """The initial stress (cells x 3 x 3, Pa) from the elastic gravity state: its vertical stress (the
        overburden in flat layers, the arching around stiff bodies), horizontal stresses by the K0 rule on
        effective stresses, sigma'_h = K0 sigma'_v, with hydrostatic pore pressure below the water table (K0 =
        -pfault_geostatic_k0, default nu/(1-nu) of each material); no initial shear."""
        return self._k0_stress(self.effective_stress(u_gravity_local)[:, 2, 2])

    def lithostatic_stress(self) -> np.ndarray:
        """The initial stress (cells x 3 x 3, Pa) of -pfault_geostatic_stress lithostatic: sigma_v the weight of the
        column above each cell's centroid (pfault.physics.geostatic.overburden, on the cells gathered on rank 0),
        horizontal stresses by the K0 rule. Collective."""
        weight = _overburden(self.comm.tompi4py(), self.mesh.coords[self.mesh.cells], self.asm.density,
                             self.settings.gravity)
        return self._k0_stress(-weight)

    def _k0_stress(self, sigma_v: np.ndarray) -> np.ndarray:
        s, asm = self.settings, self.asm
        nu = asm.lam / (2 * (asm.lam + asm.mu))
        return gs.k0_stress(sigma_v, asm.centroids[:, 2], asm.alpha, nu, s.k0, s.water_density, s.gravity,
                            s.water_table)

    def effective_stress(self, u_local: np.ndarray) -> np.ndarray:
        """Incremental effective stress C:eps per cell (nc, 3, 3), its mean over the cell: of the P1 displacements
        of ``u_local`` and, in the cells beside a fault face, of the face bubbles recovered from u_local (its
        multipliers) under the bubbles' load last set."""
        sig = self.asm.effective_stress(u_local)
        if self.faults is not None:
            f = self.faults
            cells = f.bubbles.cell
            eps = f.bubbles.cell_strain(u_local, f.tractions(u_local) - f.t0)
            sig[cells] += el.stress(eps, self.asm.lam[cells], self.asm.mu[cells])
        return sig

    def cell_total_stress(self, u_local: np.ndarray, dp: np.ndarray, sigma0: np.ndarray | None) -> np.ndarray:
        """Total stress per cell: initial + C:eps(u) - alpha dp I (dp per cell, Pa; ``Loads.cell_dp``), with the
        face bubbles' strain in the cells beside a fault (``effective_stress``)."""
        sig = self.effective_stress(u_local)
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
        F.axpy(-1.0, self.loads.f)
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
        self.loads.destroy()
        for obj in {id(o): o for o in (self.K, self.J, self.nullspace)}.values():
            obj.destroy()


def _overburden(mpi: Any, cell_coords: np.ndarray, density: np.ndarray, gravity: float) -> np.ndarray:
    """The overburden (Pa) at the centroids of this rank's cells (``cell_coords``: n x 4 x 3): the cells of every
    rank gathered on rank 0 (their vertices found again by their coordinates: a split fault's two copies of a vertex
    are one there, the column crosses the fault as if glued), the columns followed there, the values sent back."""
    parts = mpi.gather((cell_coords, density))

    def columns():
        weight = gs.overburden(np.concatenate([c for c, _ in parts]), np.concatenate([d for _, d in parts]), gravity)
        return np.split(weight, np.cumsum([len(d) for _, d in parts])[:-1])
    return mpi.scatter(run_on_root(mpi, columns))


def _to_owners(K: Any, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global (row, col) pairs of any rank's rows -> those of the rows this rank owns, from all ranks."""
    comm = K.getComm().tompi4py()
    if comm.size == 1:
        return rows, cols
    ranges = np.asarray(K.getOwnershipRanges())
    owner = np.searchsorted(ranges, rows, side="right") - 1
    parts = comm.alltoall([(rows[owner == r], cols[owner == r]) for r in range(comm.size)])
    return (np.concatenate([p[0] for p in parts]).astype(np.int64),
            np.concatenate([p[1] for p in parts]).astype(np.int64))


def _extend_pattern(K0: Any, rows: np.ndarray, cols: np.ndarray, bs: int = 1) -> Any:
    """A new AIJ matrix (block size bs) with K0's values and pattern plus explicit zeros at (rows, cols) (owned
    rows)."""
    rstart, rend = K0.getOwnershipRange()
    indptr, indices, values = K0.getValuesCSR()
    nrows = rend - rstart
    rows = np.asarray(rows, np.int64) - rstart
    if len(rows) and (rows.min() < 0 or rows.max() >= nrows):
        raise RuntimeError("extra pattern rows must be owned")
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
