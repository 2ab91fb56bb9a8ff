"""DMPlex from a SerialMesh on rank 0, partitioned by a graph partitioner and distributed by DMPlexDistribute.

Point data (materials, boundary faces and constraints, the ground surface, the faults' faces and sides) are
DMLabels on the serial DMPlex's cells and vertices (see the label names below); DMPlexDistribute migrates them
with their points, and the local mesh reads them back as arrays. Output fields come back to rank 0 in the serial
numbering through the migration PetscSF returned by DMPlexDistribute.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .fault import _components
from .serial import TET_FACES, face_keys

if TYPE_CHECKING:
    from .fault import FaultSplit
    from .serial import SerialMesh

# DMLabels on the mesh, named for what they hold; a scene has those that hold points. The mesh is not interpolated
# (cells and vertices only): a face is local face k of a cell (opposite its local vertex k, serial.TET_FACES), and a
# label on faces lives on the cells with the value 4 * index + k (a cell with several such faces has several values).
MATERIAL = "material"                           # cells: material index
BOUNDARY_FACE = "boundary_face"                 # cells: 4 * boundary + k, face k under the boundary's tractions
FAULT_FACE = "fault_face"                       # cells: 4 * fault + k, face k on the fault, the cell on its minus side
FAULT_SIDE = "fault_side"                       # cells: bits 7k..7k+6 the piece of vertex k's star the cell uses
                                                # (pfault.mesh.fault: 0 off the faults and on the minus side)
BOUNDARY_CONSTRAINT = "boundary_constraint"     # vertices: constraint mask (bit i: displacement component i fixed;
                                                # solver.flow.FIXED_HEAD_BIT: head fixed)
DISPLACEMENT_BOUNDARY = "displacement_boundary"  # vertices: index of the prescribed-displacement boundary
GROUND_SURFACE = "ground_surface"               # vertices: 1 on the ground surface
FAULT_SPLIT = "fault_split"                     # vertices: the pieces of a split fault vertex's star, minus one
SIDE_BITS, SIDE_MASK = 7, 127                   # fault_side: 4 x 7 bits fit a 32-bit PetscInt (pfault.mesh.fault)
LABELS = (MATERIAL, BOUNDARY_FACE, FAULT_FACE, FAULT_SIDE, BOUNDARY_CONSTRAINT, DISPLACEMENT_BOUNDARY,
          GROUND_SURFACE, FAULT_SPLIT)


@dataclass
class LocalMesh:
    dm: PETSc.DMPlex            # holds the labels above on its local points
    coords: np.ndarray          # (nv, 3) local vertices (owned and ghost)
    cells: np.ndarray           # (nc, 4) local vertex indices
    cell_material: np.ndarray   # (nc,) material index
    cell_face_tag: np.ndarray   # (nc, 4) boundary with tractions on local face k, -1: none
    cell_side: np.ndarray       # (nc, 4) the piece of a split fault vertex's star the cell uses (0: the first)
    cell_fault_face: np.ndarray  # (nc, 4) serial id of the fault face on local face k when this cell is its minus
                                 # cell, else -1
    vert_constraint: np.ndarray  # (nv,) constraint mask (bit i: component i fixed)
    vert_ground: np.ndarray     # (nv,) 1 on the ground surface, else 0
    vert_sides: np.ndarray      # (nv,) pieces of a split fault vertex's star (2, 3 or more at junctions), else 1
    vert_displacement_bc: np.ndarray  # (nv,) index of the prescribed-displacement boundary, -1: none
    cell_serial: np.ndarray     # (nc,) serial cell id
    vert_serial: np.ndarray     # (nv,) serial vertex id
    vert_owned: np.ndarray      # (nv,) bool
    v_start: int
    migration: PETSc.SF | None
    n_global_vertices: int
    n_global_cells: int

    @property
    def vert_data(self) -> np.ndarray:
        """(nv, 4) per-vertex columns: constraint mask, ground-surface flag, displacement sides, displacement
        boundary (the layout readers of ``vert_data[:, 0]`` and ``vert_data[:, 1]`` expect)."""
        return np.column_stack([self.vert_constraint, self.vert_ground, self.vert_sides, self.vert_displacement_bc])


def dual_graph(tets: np.ndarray, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """Cells sharing a face, as CSR (row offsets, sorted columns) over the cells of ``tets``."""
    keys = face_keys(tets[:, TET_FACES].reshape(-1, 3), nv)
    order = np.argsort(keys)
    sk = keys[order]
    pair = np.nonzero(sk[1:] == sk[:-1])[0]
    a, b = order[pair], order[pair + 1]            # cell * 4 + local face, on either side of a face
    none = np.iinfo(np.int64).max
    neighbour = np.full(4 * len(tets), none)
    neighbour[a], neighbour[b] = b // 4, a // 4
    neighbour = np.sort(neighbour.reshape(-1, 4), axis=1)
    has = neighbour != none
    offsets = np.zeros(len(tets) + 1, dtype=PETSc.IntType)
    np.cumsum(has.sum(axis=1), out=offsets[1:])
    return offsets, neighbour[has].astype(PETSc.IntType)


def _set_partition(dm, tets, nv, together=None):
    """Partition the cells (all on rank 0) for DMPlexDistribute. ``together`` (n, 2): pairs of cells to keep on one
    rank (the two cells of each fault face, whose face bubbles are condensed together, pfault.faults.faces).

    The cells' dual graph is built here from the face keys and partitioned by PETSc's MatPartitioning (PT-Scotch,
    or ParMETIS if PETSc has it; ``-mat_partitioning_type`` chooses), handed to the distribution as a shell
    partition. DMPlex's own graph construction on an uninterpolated mesh takes about 10 times longer (7.8 s
    against 0.9 s for a million tetrahedra). ``-petscpartitioner_type`` chooses PETSc's mesh partitioner instead,
    as does a PETSc built without a graph partitioner.
    """
    comm = dm.getComm()
    part = dm.getPartitioner()
    graph_type = next((t for t in ("parmetis", "ptscotch") if PETSc.Sys.hasExternalPackage(t)), None)
    if comm.size == 1 or PETSc.Options().hasName("petscpartitioner_type") or graph_type is None:
        part.setFromOptions()
        part.destroy()      # our reference; the DM keeps its own
        return
    nc = 0 if tets is None else len(tets)
    offsets, cols = dual_graph(tets, nv) if nc else (np.zeros(1, PETSc.IntType), np.zeros(0, PETSc.IntType))
    n_global = comm.tompi4py().allreduce(nc)
    graph = PETSc.Mat().createAIJ(((nc, n_global), (nc, n_global)), csr=(offsets, cols, np.ones(len(cols))),
                                  comm=comm)
    # PT-Scotch 7 partitions with several threads unless told otherwise, and its threads' races make the partition
    # differ from run to run (two-blocks scene, 2 ranks: 16/16 or 10/22 fault faces per rank), and with it the
    # roundoff and the iterative solvers' iteration counts. One thread per rank: the same partition every run
    os.environ.setdefault("SCOTCH_PTHREAD_NUMBER", "1")
    mp = PETSc.MatPartitioning().create(comm)
    mp.setAdjacency(graph)
    mp.setType(graph_type)
    # PT-Scotch's "quality" strategy: a smaller cut for no measurable time (1M-tet box: mesh phase 1.85-1.91 s
    # against 1.83-1.95 s), and MUMPS factors the resulting numbering faster (paper-size calibrated Queretaro,
    # first 5 years: 2.9 s per factorisation against 3.6 s with the default strategy, 3.5 s "speed", 3.1 s
    # "balance")
    opts = PETSc.Options()
    strategy = "mat_partitioning_ptscotch_strategy"
    ours = not opts.hasName(strategy)
    if ours:
        opts.setValue(strategy, "quality")
    mp.setFromOptions()
    if ours:
        opts.delValue(strategy)     # (unread when -mat_partitioning_type picks another partitioner)
    target = PETSc.IS()
    reset_partitioner_random_state()
    mp.apply(target)
    rank_of = target.getIndices()
    if together is not None and len(together):
        # each set of cells joined by fault faces goes to the rank of its smallest cell
        a = np.concatenate([together[:, 0], together[:, 1]])
        label, _ = _components(nc, a, np.concatenate([together[:, 1], together[:, 0]]))
        rank_of = rank_of[label]
    sizes = np.bincount(rank_of, minlength=comm.size).astype(PETSc.IntType)
    points = np.argsort(rank_of, kind="stable").astype(PETSc.IntType)
    part.setType(PETSc.Partitioner.Type.SHELL)
    part.setShellPartition(comm.size, sizes, points)
    part.destroy()
    for obj in (target, mp, graph):
        obj.destroy()


def build(comm: PETSc.Comm, serial: SerialMesh | None, cell_face_tag: np.ndarray | None = None,
          vert_constraint: np.ndarray | None = None, vert_ground: np.ndarray | None = None,
          split: FaultSplit | None = None) -> LocalMesh:
    """Create, label, distribute and localise the mesh. ``serial`` and the per-entity arrays live on rank 0:
    ``cell_face_tag`` (nc, 4) boundary with tractions on each local face (-1: none), ``vert_constraint`` (nv,)
    constraint masks, ``vert_ground`` (nv,) ground-surface flags or (nv, 2) flags and prescribed-displacement
    boundaries (-1: none), ``split`` the faults' FaultSplit."""
    rank = comm.rank
    itype = PETSc.IntType
    serial_tets = None
    if rank == 0:
        assert serial is not None
        serial_tets = serial.tets
        cells = serial.tets.astype(itype)
        coords = serial.points
        nc, nv = len(cells), len(coords)
    else:
        cells = np.zeros((0, 4), itype)
        coords = np.zeros((0, 3))
        nc = nv = 0
    dm = PETSc.DMPlex().createFromCellList(3, cells, coords, interpolate=False, comm=comm)
    dm.setName("mesh")
    labels, fault_keys = {}, None
    if rank == 0:
        labels = _serial_labels(serial, cell_face_tag, vert_constraint, vert_ground, split)
        if split is not None:
            fault_keys = 4 * split.minus_cell + split.minus_lface     # (cell, local face) of each fault face
    nc, nv, names, fault_keys = comm.tompi4py().bcast((nc, nv, list(labels), fault_keys) if rank == 0 else None)
    for name in names:      # the labels that hold points, on every rank in the same order
        dm.createLabel(name)
        if rank == 0:
            _set_label(dm.getLabel(name), *labels[name])
    together = np.column_stack([split.minus_cell, split.plus_cell]) if rank == 0 and split is not None else None
    _set_partition(dm, serial_tets, nv, together)
    migration = dm.distribute() if comm.size > 1 else None      # migrates the labels with their points
    return _localise(dm, migration, nc, nv, fault_keys)


def _localise(dm, migration, nc, nv, fault_keys):
    """The LocalMesh of a distributed DM: connectivity, ownership, serial ids and the labels as arrays.
    ``fault_keys``: 4 * minus cell + local face of each fault face in serial order (None: no faults)."""
    p_start, p_end = dm.getChart()
    c_start, c_end = dm.getHeightStratum(0)
    v_start, v_end = dm.getDepthStratum(0)
    assert c_start == 0 and c_end == v_start, "expected cells before vertices in the chart"
    cells, verts = (dm, c_start, c_end), (dm, v_start, v_end)
    serial_id = _serial_points(migration, p_end - p_start)
    cell_serial = serial_id[c_start:c_end]
    # ownership from the point SF: leaves of the point SF are ghosts
    owned = np.ones(v_end - v_start, dtype=bool)
    ilocal = dm.getPointSF().getGraph()[1] if migration is not None else None
    if ilocal is not None and len(ilocal):
        ghosts = np.asarray(ilocal)
        ghosts = ghosts[(ghosts >= v_start) & (ghosts < v_end)] - v_start
        owned[ghosts] = False
    fault = _face_values(*cells, FAULT_FACE)
    fault_face = np.full(fault.shape, -1, np.int64)
    if fault_keys is not None:
        cell, k = np.nonzero(fault >= 0)
        order = np.argsort(fault_keys)
        fault_face[cell, k] = order[np.searchsorted(fault_keys[order], 4 * cell_serial[cell] + k)]
    pieces = _point_values(*cells, FAULT_SIDE, 0)
    return LocalMesh(dm=dm, coords=dm.getCoordinatesLocal().getArray().reshape(-1, 3).copy(),
                     cells=_local_cells(dm, c_start, c_end, v_start),
                     cell_material=_point_values(*cells, MATERIAL, -1),
                     cell_face_tag=_face_values(*cells, BOUNDARY_FACE),
                     cell_side=(pieces[:, None] >> (SIDE_BITS * np.arange(4))) & SIDE_MASK, cell_fault_face=fault_face,
                     vert_constraint=_point_values(*verts, BOUNDARY_CONSTRAINT, 0),
                     vert_ground=_point_values(*verts, GROUND_SURFACE, 0),
                     vert_sides=1 + _point_values(*verts, FAULT_SPLIT, 0),
                     vert_displacement_bc=_point_values(*verts, DISPLACEMENT_BOUNDARY, -1),
                     cell_serial=cell_serial, vert_serial=serial_id[v_start:v_end] - nc, vert_owned=owned,
                     v_start=v_start, migration=migration, n_global_cells=nc, n_global_vertices=nv)


def _serial_labels(serial, cell_face_tag, vert_constraint, vert_ground, split):
    """{label: (points, values)} on the serial mesh's points (cells [0, nc), vertices [nc, nc + nv)), for the
    labels that hold points."""
    nc, nv = len(serial.tets), len(serial.points)
    out = {MATERIAL: (np.arange(nc), serial.cell_material)}
    if cell_face_tag is not None:
        cell, k = np.nonzero(np.asarray(cell_face_tag) >= 0)
        out[BOUNDARY_FACE] = (cell, 4 * cell_face_tag[cell, k] + k)
    if split is not None:
        out[FAULT_FACE] = (split.minus_cell, 4 * split.fault_id + split.minus_lface)
        pieces = split.cell_side @ (1 << (SIDE_BITS * np.arange(4)))
        cell = np.flatnonzero(pieces)
        out[FAULT_SIDE] = (cell, pieces[cell])
    if vert_constraint is not None:
        v = np.flatnonzero(vert_constraint)
        out[BOUNDARY_CONSTRAINT] = (nc + v, vert_constraint[v])
    if vert_ground is not None:
        vg = np.asarray(vert_ground).reshape(nv, -1)
        v = np.flatnonzero(vg[:, 0])
        out[GROUND_SURFACE] = (nc + v, vg[v, 0])
        if vg.shape[1] > 1:
            v = np.flatnonzero(vg[:, 1] >= 0)
            out[DISPLACEMENT_BOUNDARY] = (nc + v, vg[v, 1])
    if split is not None:
        v = np.flatnonzero(split.vert_sides > 1)
        out[FAULT_SPLIT] = (nc + v, split.vert_sides[v] - 1)
    return {name: out[name] for name in LABELS if name in out and len(out[name][0])}


def _set_label(label, points, values):
    """Give ``points`` their ``values`` in ``label``: one index set per value (a point may have several)."""
    points, values = np.asarray(points, dtype=np.int64), np.asarray(values, dtype=np.int64)
    order = np.lexsort((points, values))
    points, values = points[order].astype(PETSc.IntType), values[order]
    starts = np.flatnonzero(np.r_[True, values[1:] != values[:-1]])
    for lo, hi in zip(starts, np.r_[starts[1:], len(values)]):
        stratum = PETSc.IS().createGeneral(points[lo:hi], comm=PETSc.COMM_SELF)
        label.setStratumIS(int(values[lo]), stratum)
        stratum.destroy()


def _strata(dm, start, end, name):
    """(point - start, value) of every point of label ``name`` in [start, end), a row per value of a point."""
    points, values = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    if dm.hasLabel(name):
        label = dm.getLabel(name)
        value_is = label.getValueIS()
        for value in value_is.getIndices():
            stratum = label.getStratumIS(value)
            p = stratum.getIndices().astype(np.int64)
            stratum.destroy()
            p = p[(p >= start) & (p < end)]
            points.append(p - start)
            values.append(np.full(len(p), value, np.int64))
        value_is.destroy()
    return np.concatenate(points), np.concatenate(values)


def _point_values(dm, start, end, name, absent):
    """(end - start,) value of label ``name`` at points [start, end), ``absent`` where it has none."""
    out = np.full(end - start, absent, np.int64)
    points, values = _strata(dm, start, end, name)
    out[points] = values
    return out


def _face_values(dm, start, end, name):
    """(end - start, 4) index held by face label ``name`` (values 4 * index + k) at each cell's local face k,
    -1 where it has none."""
    out = np.full((end - start, 4), -1, np.int64)
    points, values = _strata(dm, start, end, name)
    out[points, values % 4] = values // 4
    return out


def _serial_points(migration, n):
    """Serial point id of each local point: its root in the migration SF (all roots are on rank 0)."""
    if migration is None:
        return np.arange(n, dtype=np.int64)
    _, ilocal, iremote = migration.getGraph()
    iremote = np.asarray(iremote).reshape(-1, 2)
    assert not np.any(iremote[:, 0]), "expected the serial mesh on rank 0"
    out = np.full(n, -1, np.int64)
    out[np.arange(n) if ilocal is None else np.asarray(ilocal)] = iremote[:, 1]
    return out


def _local_cells(dm, c_start, c_end, v_start):
    """(nc, 4) local vertex indices of each cell, in the order the serial mesh gave them (DMPlex keeps cones)."""
    cones = np.concatenate(list(map(dm.getCone, range(c_start, c_end)))) if c_end > c_start else np.zeros(0)
    return cones.astype(np.int64).reshape(-1, 4) - v_start


def _gather(mesh, values, offset, count):
    """Reduce per-point values of local points [offset, offset + len(values)) to rank 0 in serial order."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    k = values.shape[1]
    if mesh.migration is None:
        return values.copy()
    p_start, p_end = mesh.dm.getChart()
    leaf = np.zeros((p_end - p_start, k))
    leaf[offset:offset + len(values)] = values
    root = np.zeros((mesh.migration.getGraph()[0], k))
    unit = MPI.DOUBLE.Create_contiguous(k)
    unit.Commit()
    mesh.migration.reduceBegin(unit, leaf, root, MPI.REPLACE)
    mesh.migration.reduceEnd(unit, leaf, root, MPI.REPLACE)
    unit.Free()
    if mesh.dm.getComm().rank == 0:
        return root[count[0]:count[1]]
    return None


def gather_vertex_values(mesh: LocalMesh, values: np.ndarray) -> np.ndarray | None:
    """Values per local vertex (nv, k) -> (n_global_vertices, k) in serial order on rank 0 (None elsewhere)."""
    return _gather(mesh, values, mesh.v_start, (mesh.n_global_cells, mesh.n_global_cells + mesh.n_global_vertices))


def gather_cell_values(mesh: LocalMesh, values: np.ndarray) -> np.ndarray | None:
    """Values per local cell (nc, k) -> (n_global_cells, k) in serial order on rank 0 (None elsewhere)."""
    return _gather(mesh, values, 0, (0, mesh.n_global_cells))


def reset_partitioner_random_state() -> None:
    """PT-Scotch's random state as a new process has it (SCOTCH_randomReset of the loaded libscotch, if any), so
    that a mesh is partitioned the same whatever was partitioned before in the same process (a driver or a test
    running scenes one after another: the second run of a scene was partitioned otherwise, and with another
    partition a direct fault solve refactored at other Newton iterations)."""
    with contextlib.suppress(OSError):
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "libscotch" in line and ".so" in line}
        for path in sorted(paths):
            lib = ctypes.CDLL(path)
            if hasattr(lib, "SCOTCH_randomReset"):
                lib.SCOTCH_randomReset()
                return
