"""Output series written by every rank at once, through HDF5's MPI-IO driver (h5py built with MPI).

Each rank writes the rows it owns (its owned vertices, its cells, the fault faces of its cells) at their
places in the serial numbering, so that the files are those the serial writer (pfault.io.output.XdmfSeries on
rank 0, from values gathered there) writes, and no field is gathered on one rank.

Rank 0 creates a series' file as in a serial run (the mesh datasets, the steps a restart copies), closes it,
and every rank opens it again with the MPI-IO driver (``ParallelSeries``). Rules of parallel HDF5 kept here:
opening, flushing and closing the file, creating groups and datasets and writing attributes are collective
(the same calls with the same arguments on every rank); a dataset's data is written by each rank
independently: the rows are first moved between the ranks (one all-to-all exchange per step and kind of
row) so that rank r holds the r-th contiguous block of the serial numbering, and each rank writes its block
as one hyperslab (writing each rank's own scattered rows as a selection of runs instead made the output of
the paper-size calibrated Queretaro scene 8 times slower than gathering it to rank 0). Rank 0 rewrites the XDMF
file after the collective calls (pfault.io.output.RunWriter.add_steps). An exception on any rank is raised
on every rank between the collective calls (pfault.errors.run_on_all).

The checkpoint (pfault.io.checkpoint) is written with the same pieces (``Rows``, ``Block``, ``open_file``,
``create_dataset``, ``write_block``) into a new file after every step.

Used when a run has more than one rank and h5py has MPI (``available``); otherwise the fields are gathered
to rank 0, as always on one rank. ``GATHER_ENV`` set in the environment forces that path on any number of
ranks (for tests that compare the two; not an option of pfault).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np

from ..errors import PfaultError, run_on_all

if TYPE_CHECKING:
    import numpy.typing as npt
    from mpi4py import MPI

    from .output import XdmfEntry

GATHER_ENV = "PFAULT_GATHERED_OUTPUT"


def available(comm: Any) -> bool:
    """Whether the series are written in parallel: more than one rank, h5py with MPI, and GATHER_ENV unset
    (the same answer on every rank; collective)."""
    from mpi4py import MPI
    mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    ok = mpi.size > 1 and not os.environ.get(GATHER_ENV)
    if ok:
        try:
            ok = bool(h5py.get_config().mpi)
        except ImportError:
            ok = False
    return mpi.allreduce(ok, op=MPI.LAND)


def as_columns(values: np.ndarray) -> np.ndarray:
    """(n, ...) values per row as (n, k) columns, k the product of the trailing dimensions: also for n = 0, a
    rank that holds no row (``reshape(n, -1)`` cannot tell k from an empty array)."""
    values = np.asarray(values)
    return values.reshape(len(values), int(np.prod(values.shape[1:], dtype=np.int64)))


def agree_shapes(comm: MPI.Comm, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``arrays`` ({name: (rows, ...) values}, the same names on every rank) with each empty one given the
    trailing shape and dtype of the ranks that hold rows of it. A rank that owns no vertex, cell or fault face
    computes its values from empty arrays, whose trailing shape or dtype may not be the others' (``np.zeros(0)``
    is (0,) float where the others have (n, 3) integers); the dataset a name becomes is made from its shape and
    dtype by collective calls, which must be the same on every rank. Ranks holding rows that disagree are a bug
    (RuntimeError on every rank). Collective (mpi4py ``comm``)."""
    mine = {k: (len(v) > 0, tuple(np.shape(v)[1:]), np.asarray(v).dtype.str) for k, v in arrays.items()}
    every = comm.allgather(mine)
    out = {}
    for key, values in arrays.items():
        held = {d[key][1:] for d in every if d[key][0]} or {every[0][key][1:]}
        if len(held) > 1:
            raise RuntimeError(f"{key}: the ranks' values differ in shape or type: {sorted(held)}")
        shape, dtype = held.pop()
        values = np.asarray(values)
        agreed = values.shape[1:] == shape and values.dtype.str == dtype
        out[key] = values if agreed else np.zeros((0,) + shape, dtype=np.dtype(dtype))
    return out


class Rows:
    """The rows of a dataset of ``total`` rows in the serial numbering that this rank holds values of: ``rows``
    in increasing order, ``take`` the index of each in this rank's array of values (``source``; default: the
    row's position in ``rows`` as given)."""

    def __init__(self, rows: np.ndarray, total: int, source: np.ndarray | None = None) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        source = np.arange(len(rows)) if source is None else np.asarray(source, dtype=np.int64)
        order = np.argsort(rows, kind="stable")
        self.rows, self.take, self.total = rows[order], source[order], int(total)

    def pick(self, values: np.ndarray) -> np.ndarray:
        """This rank's values of its rows, in row order."""
        return np.ascontiguousarray(np.asarray(values)[self.take])


class Block:
    """How this rank's rows (``Rows``) reach the contiguous block of the serial numbering it writes: rank r of
    n writes rows [start, stop) with start = r * ceil(total / n); ``send`` splits this rank's values (in row
    order) by the rank whose block holds them, ``place`` puts the values received (in rank order) at their
    places in the block. Made once per kind of row (collective).

    The values move in one MPI_Alltoallv of whole rows (a contiguous type of the row's bytes): mpi4py's
    pickling all-to-all took 29 ms for 192,000 x 9 doubles on 2 ranks where this takes 4 ms."""

    def __init__(self, comm: MPI.Comm, rows: Rows) -> None:
        size, rank = comm.size, comm.rank
        per = -(-rows.total // size) if rows.total else 0
        self.start, self.stop = min(rank * per, rows.total), min((rank + 1) * per, rows.total)
        dest = rows.rows // per if per else np.zeros(len(rows.rows), np.int64)
        self.send = np.searchsorted(dest, np.arange(1, size))            # split points (rows are sorted)
        got = comm.alltoall(np.split(rows.rows, self.send))
        self.place = np.concatenate(got) - self.start if got else np.zeros(0, np.int64)
        self.send_counts = np.diff(np.concatenate([[0], self.send, [len(rows.rows)]])).astype(np.int64)
        self.recv_counts = np.array([len(g) for g in got], dtype=np.int64)

    def gather(self, comm: MPI.Comm, values: np.ndarray) -> np.ndarray:
        """This rank's block of the dataset from every rank's values (in row order); collective."""
        from mpi4py import MPI
        values = np.ascontiguousarray(values)
        shape = values.shape[1:]
        got = np.empty((int(self.recv_counts.sum()),) + shape, dtype=values.dtype)
        row_bytes = values.dtype.itemsize * int(np.prod(shape, dtype=np.int64))
        if row_bytes:
            row = MPI.BYTE.Create_contiguous(row_bytes).Commit()
            try:
                comm.Alltoallv([values, (self.send_counts, _starts(self.send_counts)), row],
                               [got, (self.recv_counts, _starts(self.recv_counts)), row])
            finally:
                row.Free()
        block = np.empty((self.stop - self.start,) + shape, dtype=values.dtype)
        if len(block):
            block[self.place] = got
        return block


def _starts(counts):
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def blocks(comm: MPI.Comm, name: str, rows: dict[str, Rows]) -> dict[str, Block]:
    """{kind: Block} of the datasets ``name`` writes, from this rank's {kind: Rows}, once it is checked that the
    ranks' rows cover each kind's datasets once. Collective (mpi4py ``comm``)."""
    kinds = sorted(rows)
    counts = comm.allreduce(np.array([len(rows[k].rows) for k in kinds], dtype=np.int64))
    bad = {k: (int(n), rows[k].total) for k, n in zip(kinds, counts) if n != rows[k].total}
    if bad:
        raise RuntimeError(f"{name}: the ranks' rows do not cover the datasets once (rows, total): {bad}")
    return {k: Block(comm, rows[k]) for k in kinds}


def open_file(comm: MPI.Comm, path: str, mode: str) -> h5py.File:
    """``path`` opened by every rank of ``comm`` (mpi4py) with HDF5's MPI-IO driver, without HDF5's file lock
    where h5py offers that (pfault.io.output.open_h5). Collective."""
    try:
        return h5py.File(path, mode, driver="mpio", comm=comm, locking=False)
    except TypeError:
        return h5py.File(path, mode, driver="mpio", comm=comm)


def create_dataset(group: h5py.Group, name: str, shape: tuple[int, ...], dtype: npt.DTypeLike) -> h5py.Dataset:
    """A dataset without fill values: every row is written (fill values would be written first, by all ranks
    together). Collective."""
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)
    return group.create_dataset(name, shape=shape, dtype=dtype, dcpl=dcpl)


def write_block(ds: h5py.Dataset, start: int, values: np.ndarray) -> None:
    """Write ``values`` into the rows [start, start + len(values)) of ``ds`` (one hyperslab; independent)."""
    if len(values):
        ds[start:start + len(values)] = values


class ParallelSeries:
    """A series (pfault.io.output.XdmfSeries) continued by every rank: ``NAME.h5`` in ``directory``, opened
    with the MPI-IO driver on ``comm``; ``rows`` {"Node": Rows, "Cell": Rows} says which rows of each kind of
    dataset this rank writes. Every method is collective."""

    def __init__(self, comm: Any, directory: str, name: str, rows: dict[str, Rows]) -> None:
        self.comm = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
        self.name, self.rows = name, rows
        self.blocks = blocks(self.comm, name, rows)
        self.h5 = run_on_all(self.comm, open_file, self.comm, os.path.join(directory, name + ".h5"), "r+")

    def write_step(self, step: int, t: float, point_data: dict[str, np.ndarray] | None = None,
                   cell_data: dict[str, np.ndarray] | None = None) -> XdmfEntry:
        """Write one step: arrays of this rank's values (local vertices or cells, as its Rows take them).
        Returns the step's XDMF entry (pfault.io.output.RunWriter.add_steps)."""
        data = [(center, key, self.blocks[center].gather(self.comm, self.rows[center].pick(value)))
                for center, values in (("Node", point_data or {}), ("Cell", cell_data or {}))
                for key, value in values.items()]
        path = f"/steps/{int(step):06d}"
        # metadata first, the same on every rank, then the data: a rank that fails to write its rows leaves
        # the file's metadata as the others have it, and the file can still be closed by all
        datasets = run_on_all(self.comm, self._create, path, int(step), float(t), data)
        try:
            run_on_all(self.comm, self._fill, datasets)
        except PfaultError:
            # shared by every rank (run_on_all): the step, whose rows are not all written, goes together
            del datasets
            del self.h5[path]
            raise
        run_on_all(self.comm, self.h5.flush)
        fields = [(key, center, ((self.rows[center].total,) + value.shape[1:], value.dtype))
                  for center, key, value in data]
        return path, float(t), sorted(fields)           # in h5py's order: by name

    def _create(self, path, step, t, data):
        """The step's group and datasets: [(dataset, first row of this rank's block, its values)]."""
        grp = self.h5.create_group(path)
        grp.attrs["step"], grp.attrs["time"] = step, t
        datasets = []
        for center, key, value in data:
            rows = self.rows[center]
            ds = create_dataset(grp, key, (rows.total,) + value.shape[1:], value.dtype)
            ds.attrs["center"] = center
            datasets.append((ds, self.blocks[center].start, value))
        return datasets

    @staticmethod
    def _fill(datasets):
        for ds, start, value in datasets:
            write_block(ds, start, value)

    def close(self) -> None:
        if self.h5 is not None:
            h5, self.h5 = self.h5, None
            run_on_all(self.comm, h5.close)

