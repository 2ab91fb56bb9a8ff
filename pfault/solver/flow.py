"""Transient groundwater flow (P1, backward Euler) that supplies the pore-pressure change to the skeleton.

    S_s dh/dt - div(K grad h) = -Q delta(wells),   h = 0 at t = 0 and on fixed-head surfaces,
    dp = rho_w g h   (Pa per cell: the cell average of the P1 head)

One-way coupling: the head does not feel the skeleton's deformation beyond the storage S_s
(see pfault.physics.flow.specific_storage). Other boundaries are no-flow (natural). The head has one
dof per mesh vertex, also at split fault vertices: faults are not hydraulic barriers here.

Discretisation
--------------
- The head lives on a clone of the mesh DM (``dm.clone()``) with its own scalar PetscSection (field
  ``head``, one dof per vertex); the displacement section is untouched. The local dof of a vertex is its
  local vertex index. Matrices come from ``createMatrix()`` of that DM (exact preallocation) and are
  filled with ``setValuesLocalRCV``: A (conductivity), M (consistent storage mass) and J = M/dt + A.
- Backward Euler: (M/dt + A) h^{n+1} = M/dt h^n - q(t^{n+1}); rows and columns of fixed-head vertices
  are replaced by the identity (h = 0 there). J is rebuilt, and the preconditioner set up again, only
  when dt changes.
- Wells are vertical line sinks along their screen: the rate is distributed along the part of the
  axis x = xw, y = yw, z_bottom <= z <= z_top inside the mesh in proportion to K (a screen across layers
  draws from each in proportion to its conductivity, as with a uniform head in the borehole), and each
  tetrahedron the axis crosses receives the exact P1 load q_a = Q int_(axis in tet) K phi_a ds /
  int_(screen) K ds. An axis along a vertical face or edge shared by several tetrahedra is given to one of
  them by a symbolic perturbation of the axis (pfault.physics.flow.vertical_line_in_tets), a rule
  based on coordinates only, so the load does not depend on the partition or numbering. Cells are not
  duplicated across ranks, so per-cell loads are summed into a local vector and added with
  localToGlobal(ADD) without double counting. The part of the screen outside the mesh is an error.
- Solver: KSP with prefix ``flow_``; code defaults, each only where the user is silent: -flow_ksp_type cg,
  -flow_pc_type hypre (BoomerAMG; gamg if PETSc has no hypre), -flow_ksp_rtol 1e-10.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..errors import InputError
from ..materials.properties import is_field
from ..physics import flow as fl
from ..physics.loading import Table
from .setup import set_default

if TYPE_CHECKING:
    from ..mesh.distributed import LocalMesh
    from ..mesh.serial import SerialMesh
    from ..options import OptionReader
    from ..scene import Material

HEAD = "head"
FIXED_HEAD_BIT = 8      # bit 3 of the vertex constraint mask (bits 0-2 are displacement components)


class FlowNotConverged(RuntimeError):
    """The flow KSP did not converge (raised on every rank: the converged reason is collective)."""


@dataclass(frozen=True)
class Well:
    x: float                      # m
    y: float                      # m
    z_top: float                  # m, top of the screen
    z_bottom: float               # m, bottom of the screen
    rate: Callable[[float], float]  # Q(t), m**3/s, positive is pumping (extraction)


def _as_well(w):
    """A Well, or a tuple (x, y, z_top, z_bottom, rate) with rate a callable Q(t) or a constant (m**3/s)."""
    if not isinstance(w, Well):
        w = Well(*w)
    if not callable(w.rate):
        q = float(w.rate)
        w = Well(w.x, w.y, w.z_top, w.z_bottom, lambda t: q)
    return w


@dataclass(frozen=True)
class FlowSettings:
    conductivity: tuple           # per material: m/s, or a field (pfault.materials.properties.FieldRef)
    storage: tuple                # per material: 1/m, a field, or None: the default from the skeleton per cell
    wells: tuple
    fixed_head_surfaces: tuple
    substeps: int
    void_ratio: tuple = ()        # per material: a number or a field (the default storage of a None entry)


# -- options ---------------------------------------------------------------------------------------
def read_flow_settings(reader: OptionReader, material_names: Sequence[str], materials: Sequence[Material],
                       surface_names: Collection[str], water_density: float, gravity: float) -> FlowSettings:
    """Flow inputs from -pfault_ options (call only when -pfault_flow is true); same verdict on every rank."""
    cond, stor, voids = [], [], []
    for name, m in zip(material_names, materials):
        p = f"pfault_material_{name}_"
        k = reader.get(p + "hydraulic_conductivity")
        if k is None:
            raise InputError(f"missing -{p}hydraulic_conductivity (m/s) for physical volume '{name}' "
                             "(needed by -pfault_flow)")
        if not is_field(k) and not k > 0:
            raise InputError(f"-{p}hydraulic_conductivity: must be positive, got {k}")
        e = reader.get(p + "void_ratio")
        if not is_field(e) and not e > 0:
            raise InputError(f"-{p}void_ratio: must be positive, got {e}")
        ss = reader.get(p + "specific_storage")
        skeleton = (m.young_modulus, m.poisson_ratio, e, m.biot_coefficient)
        # (a material with memory has no drained modulus: its default storage is its cells' elastic skeletal
        # storage at their reference modulus, pfault.materials.properties.flow_cell_properties)
        if ss is None and m.young_modulus is not None and not any(is_field(v) for v in skeleton):
            ss = float(fl.specific_storage(m.young_modulus, m.poisson_ratio, e, m.biot_coefficient,
                                           water_density, gravity))
        elif ss is not None and not is_field(ss) and not ss > 0:
            raise InputError(f"-{p}specific_storage: must be positive, got {ss}")
        cond.append(k)
        stor.append(ss)
        voids.append(e)
    xy = reader.get("pfault_flow_wells")
    screen = reader.get("pfault_flow_well_screen")
    rate = reader.get("pfault_flow_well_rate")
    wells: tuple[Well, ...] = ()
    if xy:
        if len(xy) % 2:
            raise InputError("-pfault_flow_wells: give x,y pairs (x1,y1,x2,y2,... in m)")
        if len(screen) != 2 or not screen[0] > screen[1]:
            raise InputError("-pfault_flow_well_screen: give z_top,z_bottom (m) with z_top > z_bottom")
        if rate is None:
            raise InputError("-pfault_flow_well_rate: give the pumping rate per well as time:rate pairs "
                             "(example: 0:0,1*year:300*L/s)")
        table = Table.from_pairs(rate)
        wells = tuple(Well(xy[i], xy[i + 1], screen[0], screen[1], table) for i in range(0, len(xy), 2))
    surfaces = tuple(reader.get("pfault_flow_fixed_head_surfaces"))
    for s in surfaces:
        if s not in surface_names:
            raise InputError(f"-pfault_flow_fixed_head_surfaces: no physical surface '{s}' in the mesh "
                             f"(surfaces: {', '.join(surface_names)})")
    substeps = reader.get("pfault_flow_substeps")
    if substeps < 1:
        raise InputError("-pfault_flow_substeps: need at least 1")
    return FlowSettings(tuple(cond), tuple(stor), wells, surfaces, substeps, tuple(voids))


def fixed_head_vertices(serial: SerialMesh, surface_names: Iterable[str]) -> np.ndarray:
    """(nv,) int 0/1 on the serial mesh (rank 0): vertices on the named physical surfaces."""
    mask = np.zeros(len(serial.points), np.int64)
    for name in surface_names:
        if name not in serial.surfaces:
            raise InputError(f"-pfault_flow_fixed_head_surfaces: no physical surface '{name}' in the mesh")
        mask[np.unique(serial.surfaces[name])] = 1
    return mask


# -- the model -------------------------------------------------------------------------------------
TIME_RTOL = 1e-12       # two times closer than this (relative; absolute near 0 s) are the same time


def after(t: float, now: float) -> bool:
    """Whether time ``t`` lies after ``now`` by more than TIME_RTOL (s)."""
    return t > now + TIME_RTOL * max(abs(t), abs(now), 1.0)


class HeadGrid:
    """The head's discrete space on a LocalMesh: a clone of the mesh DM (``dm``) with a scalar section, one dof
    per vertex (the local dof of a vertex is its local vertex index), and its fixed-head rows (``fixed_owned``:
    owned local dofs, ``fixed_rows``: their global rows)."""

    def __init__(self, mesh: LocalMesh, fixed_head: np.ndarray | None = None) -> None:
        self.mesh = mesh
        self.comm = mesh.dm.getComm()
        nv = len(mesh.coords)
        self.dm = mesh.dm.clone()
        self.dm.setName("head_mesh")
        self.section = self._scalar_section(nv)
        self.dm.setSection(self.section)
        self.cells = mesh.cells.astype(PETSc.IntType)
        fixed = np.zeros(nv, bool) if fixed_head is None else np.asarray(fixed_head, bool)
        g = self.to_global(fixed.astype(float), PETSc.InsertMode.INSERT_VALUES)
        start, _ = g.getOwnershipRange()
        self.fixed_owned = np.nonzero(g.getArray() > 0.5)[0].astype(PETSc.IntType)
        self.fixed_rows = self.fixed_owned + start
        g.destroy()

    def _scalar_section(self, nv: int) -> PETSc.Section:
        sec = PETSc.Section().create(comm=self.comm)
        sec.setNumFields(1)
        sec.setFieldName(0, HEAD)
        sec.setFieldComponents(0, 1)
        sec.setChart(*self.dm.getChart())
        # no array setter in petsc4py 3.18: one call per vertex
        for v in range(self.mesh.v_start, self.mesh.v_start + nv):
            sec.setDof(v, 1)
            sec.setFieldDof(v, 0, 1)
        sec.setUp()
        # only vertices carry dofs and they follow the cells in the chart: local dof = local vertex index
        if nv:
            assert sec.getOffset(self.mesh.v_start) == 0 and sec.getOffset(self.mesh.v_start + nv - 1) == nv - 1
        return sec

    def assemble(self, ke: np.ndarray) -> PETSc.Mat:
        """The matrix of the (nc, 4, 4) element matrices ``ke``."""
        mat = self.dm.createMatrix()
        mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        mat.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
        chunk = 65536
        for s in range(0, len(ke), chunk):
            e = slice(s, s + chunk)
            mat.setValuesLocalRCV(self.cells[e], self.cells[e], ke[e].reshape(-1, 16),
                                  addv=PETSc.InsertMode.ADD_VALUES)
        mat.assemble()
        return mat

    def to_global(self, local_array: np.ndarray, mode: PETSc.InsertMode = PETSc.InsertMode.ADD_VALUES) -> PETSc.Vec:
        """A new global Vec of per-local-vertex values (added over ranks, or inserted)."""
        lv = self.dm.getLocalVec()
        lv.setArray(local_array)
        g = self.dm.createGlobalVec()
        self.dm.localToGlobal(lv, g, addv=mode)
        self.dm.restoreLocalVec(lv)
        return g

    def to_local(self, g: PETSc.Vec) -> np.ndarray:
        """The values of global Vec ``g`` at the local vertices (owned and ghost)."""
        lv = self.dm.getLocalVec()
        self.dm.globalToLocal(g, lv, addv=PETSc.InsertMode.INSERT_VALUES)
        out = lv.getArray().copy()
        self.dm.restoreLocalVec(lv)
        return out

    def set_global(self, local_array: np.ndarray, g: PETSc.Vec) -> None:
        """Global Vec ``g`` set from per-local-vertex values."""
        lv = self.dm.getLocalVec()
        lv.setArray(local_array)
        self.dm.localToGlobal(lv, g, addv=PETSc.InsertMode.INSERT_VALUES)
        self.dm.restoreLocalVec(lv)

    def destroy(self) -> None:
        self.section.destroy()
        self.dm.destroy()


class WellLoads:
    """The wells (``wells``) and the load of a unit rate of each (``loads``: global Vecs that sum to 1), spread
    along its screen in proportion to K."""

    def __init__(self, grid: HeadGrid, wells: Iterable[Well | tuple], grad: np.ndarray, vol: np.ndarray,
                 conductivity: np.ndarray) -> None:
        self.wells = tuple(_as_well(w) for w in wells)
        self.loads = [self._load(grid, w, grad, vol, conductivity) for w in self.wells]

    @staticmethod
    def _load(grid, well, grad, vol, conductivity):
        mesh = grid.mesh
        x0 = mesh.coords[mesh.cells[:, 0]]
        mpi = grid.comm.tompi4py()
        screen = well.z_top - well.z_bottom
        if not screen > 0:
            raise InputError(f"well at ({well.x:g}, {well.y:g}): screen top must lie above its bottom")
        # the tie-breaking perturbation must point into the mesh: on a boundary (e.g. a symmetry plane at
        # x = max) the first directions may miss it; the first side that covers the screen is used
        best = 0.0
        for side in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
            length, mid = fl.vertical_line_in_tets(grad, vol, x0, well.x, well.y, well.z_bottom, well.z_top, side)
            covered = mpi.allreduce(float(length.sum()), op=MPI.SUM)
            best = max(best, covered)
            if abs(covered - screen) <= 1e-8 * screen:
                break
        else:
            raise InputError(f"well at ({well.x:g}, {well.y:g}): only {best:g} m of its {screen:g} m screen "
                             f"(z {well.z_bottom:g} to {well.z_top:g} m) lie inside the mesh; the whole "
                             "screen must")
        wk = length * conductivity
        total_k = mpi.allreduce(float(wk.sum()), op=MPI.SUM)
        loc = np.bincount(mesh.cells.ravel(), weights=(wk[:, None] * mid).ravel() / total_k,
                          minlength=len(mesh.coords))
        return grid.to_global(loc)

    def subtract_from(self, b: PETSc.Vec, t: float) -> None:
        """b -= sum of the wells' loads at their rates Q(t) (positive is pumping)."""
        for well, load in zip(self.wells, self.loads):
            b.axpy(-float(well.rate(t)), load)

    def destroy(self) -> None:
        for load in self.loads:
            load.destroy()
        self.loads = []


class GroundwaterFlow:
    """P1 transient flow on a LocalMesh; the mechanics read it through pfault.sources.FlowSource.

    mesh: LocalMesh; conductivity, storage: (nc,) per local cell (m/s, 1/m) or scalars; wells: Wells or
    tuples (x, y, z_top, z_bottom, rate), rate a callable Q(t) or a constant (m**3/s, positive is pumping,
    evaluated at the end of each step); fixed_head: (nv,) bool per local vertex (h = 0 there);
    substeps: backward-Euler steps per ``advance_to`` call; lumped_mass: lumped instead of consistent
    storage matrix; prefix: options prefix of the KSP.

    After construction: ``advance_to(t)``, ``step(dt)``, ``cell_dp()`` (dp per local cell at ``time``, Pa),
    ``vertex_head()`` (h per local vertex, m), ``time``, ``history`` (one record per step: time_s, dt_s, ksp_its,
    reason), ``grid`` (HeadGrid: the head's DM), ``wells`` (WellLoads), ``h`` (the head's global Vec),
    ``destroy()``.
    """

    def __init__(self, mesh: LocalMesh, conductivity: float | np.ndarray, storage: float | np.ndarray,
                 wells: Iterable[Well | tuple] = (), fixed_head: np.ndarray | None = None, substeps: int = 1,
                 water_density: float = 1000.0, gravity: float = 9.80665, lumped_mass: bool = False,
                 prefix: str = "flow_", t0: float = 0.0) -> None:
        self.comm = mesh.dm.getComm()
        self.substeps = int(substeps)
        self.rho_g = water_density * gravity
        self.prefix = prefix
        self.time = float(t0)
        self.history: list[dict[str, Any]] = []
        self._dt: float | None = None
        self.log_assembly = PETSc.Log.Event("pfaultFlowAssemble")
        self.log_solve = PETSc.Log.Event("pfaultFlowSolve")
        nc, nv = len(mesh.cells), len(mesh.coords)
        conductivity = np.broadcast_to(np.asarray(conductivity, float), (nc,))
        storage = np.broadcast_to(np.asarray(storage, float), (nc,))

        self.grid = HeadGrid(mesh, fixed_head)
        self.log_assembly.begin()
        grad, vol = fl.tet_geometry(mesh.coords[mesh.cells])
        self.A = self.grid.assemble(fl.conductivity(grad, vol, conductivity))
        self.M = self.grid.assemble(fl.mass(vol, storage, lumped=lumped_mass))
        self.J = self.grid.dm.createMatrix()
        self.J.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
        self.log_assembly.end()

        self.h = self.grid.dm.createGlobalVec()
        self.h.setName(HEAD)
        self.b = self.h.duplicate()
        self.h_local = np.zeros(nv)
        self.wells = WellLoads(self.grid, wells, grad, vol, conductivity)
        self.ksp = self._create_ksp()

    # -- setup -------------------------------------------------------------------------------------
    def _create_ksp(self):
        p = self.prefix
        opts = PETSc.Options()
        if not (opts.hasName(p + "ksp_type") or opts.hasName(p + "pc_type")):
            set_default(p + "ksp_type", "cg")
            set_default(p + "pc_type", "hypre" if PETSc.Sys.hasExternalPackage("hypre") else "gamg")
        set_default(p + "ksp_rtol", "1e-10")
        ksp = PETSc.KSP().create(comm=self.comm)
        ksp.setOptionsPrefix(p)
        ksp.setOperators(self.J, self.J)
        ksp.setInitialGuessNonzero(True)
        ksp.setFromOptions()
        return ksp

    def _set_dt(self, dt):
        """J = A + M/dt with identity rows/columns at fixed heads; the PC is set up again."""
        self.log_assembly.begin()
        self.A.copy(self.J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.J.axpy(1.0 / dt, self.M, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.J.zeroRowsColumns(self.grid.fixed_rows, diag=1.0)
        self.ksp.setOperators(self.J, self.J)
        self._dt = dt
        self.log_assembly.end()

    # -- time stepping ---------------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        return len(self.wells.wells) > 0

    def step(self, dt: float) -> None:
        """One backward-Euler step of length dt (s)."""
        if self._dt is None or abs(dt - self._dt) > 1e-12 * dt:
            self._set_dt(dt)
        t_new = self.time + dt
        self.log_solve.begin()
        self.M.mult(self.h, self.b)
        self.b.scale(1.0 / dt)
        self.wells.subtract_from(self.b, t_new)
        self.b.getArray()[self.grid.fixed_owned] = 0.0
        self.ksp.solve(self.b, self.h)
        self.log_solve.end()
        reason = self.ksp.getConvergedReason()
        self.history.append({"time_s": t_new, "dt_s": dt, "ksp_its": int(self.ksp.getIterationNumber()),
                             "reason": int(reason)})
        if reason <= 0:
            raise FlowNotConverged(f"groundwater flow: KSP {self.prefix} did not converge at t = {t_new:g} s "
                                   f"(reason {reason})")
        self.time = t_new
        self.h_local = self.grid.to_local(self.h)

    def advance_to(self, t: float) -> None:
        """Take ``substeps`` equal backward-Euler steps from the current time to t (nothing if t is reached)."""
        t = float(t)
        if after(self.time, t):
            raise ValueError(f"groundwater flow is at t = {self.time:g} s and cannot go back to {t:g} s")
        if not after(t, self.time):
            return
        t_start = self.time
        for k in range(1, self.substeps + 1):
            target = t_start + (t - t_start) * k / self.substeps
            self.step(target - self.time)
        self.time = t

    # -- outputs ----------------------------------------------------------------------------------------
    def vertex_head(self) -> np.ndarray:
        """Head change h (m) at the local vertices (owned and ghost), at the current time."""
        return self.h_local.copy()

    def restore(self, h_local: np.ndarray, time: float, history: Iterable[dict[str, Any]] = ()) -> None:
        """Continue from a saved state (restart): head change h per local vertex (m, owned and ghost), the
        model time (s) and its step records."""
        self.h_local = np.array(h_local, dtype=float, copy=True)
        self.grid.set_global(self.h_local, self.h)
        self.time = float(time)
        self.history = [dict(r) for r in history]

    def cell_dp(self) -> np.ndarray:
        """Pore-pressure change dp = rho_w g h (Pa) per local cell at the model's current time (``time``); h is
        the cell average of the P1 head."""
        return self.rho_g * self.h_local[self.grid.mesh.cells].mean(axis=1)

    def destroy(self) -> None:
        for obj in [self.ksp, self.A, self.M, self.J, self.h, self.b]:
            obj.destroy()
        self.wells.destroy()
        self.grid.destroy()
