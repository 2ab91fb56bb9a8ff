"""DMPlex from a SerialMesh on rank 0, partitioned by a graph partitioner and distributed by DMPlexDistribute.

Per-point data (cell connectivity in serial vertex ids, materials, boundary tags, constraints) travel
to their new owners through the migration PetscSF returned by DMPlexDistribute; output fields come
back to rank 0 in the serial numbering through the same SF.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .serial import TET_FACES, face_keys


@dataclass
class LocalMesh:
    dm: PETSc.DMPlex
    coords: np.ndarray          # (nv, 3) local vertices (owned and ghost)
    cells: np.ndarray           # (nc, 4) local vertex indices
    cell_data: np.ndarray       # (nc, k) int payload columns (see CELL_COLUMNS)
    vert_data: np.ndarray       # (nv, k) int payload columns (see VERT_COLUMNS)
    cell_serial: np.ndarray     # (nc,) serial cell id
    vert_serial: np.ndarray     # (nv,) serial vertex id
    vert_owned: np.ndarray      # (nv,) bool
    v_start: int
    migration: PETSc.SF | None
    n_global_vertices: int
    n_global_cells: int

    @property
    def cell_material(self):
        return self.cell_data[:, 4]

    @property
    def cell_face_tag(self):
        return self.cell_data[:, 5:9]

    @property
    def cell_side(self):
        """(nc,4) 1 where the cell uses the plus-side dofs of a split fault vertex."""
        return self.cell_data[:, 9:13]

    @property
    def cell_fault_face(self):
        """(nc,4) serial id of the fault face on local face k when this cell is its minus cell, else -1."""
        return self.cell_data[:, 13:17]

    @property
    def vert_sides(self):
        return self.vert_data[:, 2]

    @property
    def vert_displacement_bc(self):
        return self.vert_data[:, 3]


# payload layout: every point row has the same number of int columns
# cells: 4 serial vertex ids, material, 4 boundary face tags (-1: none), 4 fault sides, 4 minus fault faces
CELL_COLUMNS = 17
# vertices: constraint mask (bit i: component i fixed), ground-surface flag, displacement sides (1 or 2),
# index of the prescribed-displacement boundary (-1: none)
VERT_COLUMNS = 4
PAYLOAD = max(CELL_COLUMNS, VERT_COLUMNS)


def _int_type(width):
    base = MPI.INT if PETSc.IntType().itemsize == 4 else MPI.INT64_T
    t = base.Create_contiguous(width)
    t.Commit()
    return t


def dual_graph(tets, nv):
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


def _set_partition(dm, tets, nv):
    """Partition the cells (all on rank 0) for DMPlexDistribute.

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
    mp.apply(target)
    rank_of = target.getIndices()
    sizes = np.bincount(rank_of, minlength=comm.size).astype(PETSc.IntType)
    points = np.argsort(rank_of, kind="stable").astype(PETSc.IntType)
    part.setType(PETSc.Partitioner.Type.SHELL)
    part.setShellPartition(comm.size, sizes, points)
    part.destroy()
    for obj in (target, mp, graph):
        obj.destroy()


def build(comm, serial, cell_face_tag=None, vert_constraint=None, vert_ground=None, split=None):
    """Create, distribute and localise the mesh. ``serial`` and the per-entity arrays live on rank 0."""
    rank = comm.rank
    itype = PETSc.IntType
    if rank == 0:
        cells = serial.tets.astype(itype)
        coords = serial.points
        nc, nv = len(cells), len(coords)
    else:
        cells = np.zeros((0, 4), itype)
        coords = np.zeros((0, 3))
        nc = nv = 0
    dm = PETSc.DMPlex().createFromCellList(3, cells, coords, interpolate=False, comm=comm)
    dm.setName("mesh")
    n_global = comm.tompi4py().bcast((nc, nv) if rank == 0 else None, root=0)

    # payload on the serial points: cells [0, nc), vertices [nc, nc + nv)
    root = np.full((nc + nv, PAYLOAD), -1, dtype=itype)
    if rank == 0:
        root[:nc, 0:4] = serial.tets
        root[:nc, 4] = serial.cell_material
        if cell_face_tag is not None:
            root[:nc, 5:9] = cell_face_tag
        root[nc:, 0] = 0 if vert_constraint is None else vert_constraint
        if vert_ground is not None:
            vg = np.asarray(vert_ground).reshape(nv, -1)
            root[nc:, 1] = vg[:, 0]
            root[nc:, 3] = vg[:, 1] if vg.shape[1] > 1 else -1
        else:
            root[nc:, 1] = 0
            root[nc:, 3] = -1
        root[nc:, 2] = 1
        root[:nc, 9:13] = 0
        if split is not None:
            root[nc:, 2] = split.vert_sides
            root[:nc, 9:13] = split.cell_side
            root[split.minus_cell, 13 + split.minus_lface] = np.arange(len(split.minus_cell))
    serial_id = np.concatenate([np.arange(nc), np.arange(nv)]).astype(itype)

    _set_partition(dm, serial.tets if rank == 0 else None, nv)
    migration = dm.distribute() if comm.size > 1 else None
    p_start, p_end = dm.getChart()
    if migration is not None:
        leaf = np.full((p_end - p_start, PAYLOAD), -1, dtype=itype)
        unit = _int_type(PAYLOAD)
        migration.bcastBegin(unit, root, leaf, MPI.REPLACE)
        migration.bcastEnd(unit, root, leaf, MPI.REPLACE)
        unit.Free()
        leaf_id = np.full(p_end - p_start, -1, dtype=itype)
        migration.bcastBegin(MPI.INT if itype().itemsize == 4 else MPI.INT64_T, serial_id, leaf_id, MPI.REPLACE)
        migration.bcastEnd(MPI.INT if itype().itemsize == 4 else MPI.INT64_T, serial_id, leaf_id, MPI.REPLACE)
    else:
        leaf, leaf_id = root, serial_id
    c_start, c_end = dm.getHeightStratum(0)
    v_start, v_end = dm.getDepthStratum(0)
    assert c_start == 0 and c_end == v_start, "expected cells before vertices in the chart"
    cell_data = np.ascontiguousarray(leaf[c_start:c_end, :CELL_COLUMNS])
    vert_data = np.ascontiguousarray(leaf[v_start:v_end, :VERT_COLUMNS])
    cell_serial = leaf_id[c_start:c_end].astype(np.int64)
    vert_serial = leaf_id[v_start:v_end].astype(np.int64)
    # local connectivity from serial vertex ids
    order = np.argsort(vert_serial)
    pos = np.searchsorted(vert_serial[order], cell_data[:, 0:4])
    local_cells = order[np.minimum(pos, len(order) - 1)] if len(order) else np.zeros((0, 4), np.int64)
    if len(local_cells) and np.any(vert_serial[local_cells] != cell_data[:, 0:4]):
        raise RuntimeError("a cell refers to a vertex that did not migrate with it")
    coords = dm.getCoordinatesLocal().getArray().reshape(-1, 3).copy()
    # ownership from the point SF: leaves of the point SF are ghosts
    owned = np.ones(v_end - v_start, dtype=bool)
    ilocal = dm.getPointSF().getGraph()[1] if comm.size > 1 else None
    if ilocal is not None and len(ilocal):
        ghosts = np.asarray(ilocal)
        ghosts = ghosts[(ghosts >= v_start) & (ghosts < v_end)] - v_start
        owned[ghosts] = False
    return LocalMesh(dm=dm, coords=coords, cells=local_cells.astype(np.int64), cell_data=cell_data.astype(np.int64),
                     vert_data=vert_data.astype(np.int64), cell_serial=cell_serial, vert_serial=vert_serial,
                     vert_owned=owned, v_start=v_start, migration=migration,
                     n_global_cells=n_global[0], n_global_vertices=n_global[1])


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


def gather_vertex_values(mesh, values):
    """Values per local vertex (nv, k) -> (n_global_vertices, k) in serial order on rank 0 (None elsewhere)."""
    return _gather(mesh, values, mesh.v_start, (mesh.n_global_cells, mesh.n_global_cells + mesh.n_global_vertices))


def gather_cell_values(mesh, values):
    """Values per local cell (nc, k) -> (n_global_cells, k) in serial order on rank 0 (None elsewhere)."""
    return _gather(mesh, values, 0, (0, mesh.n_global_cells))
