"""Output series written by every rank at once, through HDF5's MPI-IO driver (h5py built with MPI).

Each rank writes the rows it owns (its owned vertices, its cells, the fault faces of its cells) at their
places in the serial numbering, so that the files are those the serial writer (pfault.io.output.XdmfSeries on
rank 0, from values gathered there) writes, and no field is gathered on one rank.

Rank 0 creates a series' file as in a serial run (the mesh datasets, the steps a restart copies), closes it,
and every rank opens it again with the MPI-IO driver (``ParallelSeries``). Rules of parallel HDF5 kept here:
opening, flushing and closing the file, creating groups and datasets and writing attributes are collective
(the same calls with the same arguments on every rank); a dataset's data is written by each rank
independently, its rows in increasing order as one selection of contiguous runs. Rank 0 rewrites the XDMF
file after the collective calls (pfault.io.output.RunWriter.add_steps). An exception on any rank is raised
on every rank between the collective calls (pfault.errors.run_on_all).

Used when a run has more than one rank and h5py has MPI (``available``); otherwise the fields are gathered
to rank 0, as always on one rank. ``GATHER_ENV`` set in the environment forces that path on any number of
ranks (for tests that compare the two; not an option of pfault).
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import PfaultError, run_on_all

GATHER_ENV = "PFAULT_GATHERED_OUTPUT"


def available(comm):
    """Whether the series are written in parallel: more than one rank, h5py with MPI, and GATHER_ENV unset
    (the same answer on every rank; collective)."""
    from mpi4py import MPI
    mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    ok = mpi.size > 1 and not os.environ.get(GATHER_ENV)
    if ok:
        try:
            import h5py
            ok = bool(h5py.get_config().mpi)
        except ImportError:
            ok = False
    return mpi.allreduce(ok, op=MPI.LAND)


class Rows:
    """The rows of a dataset of ``total`` rows in the serial numbering that this rank writes: ``rows`` in
    increasing order, ``take`` the index of each in this rank's array of values (``source``; default: the
    row's position in ``rows`` as given), ``runs`` (k, 2) their contiguous [start, stop) stretches."""

    def __init__(self, rows, total, source=None):
        rows = np.asarray(rows, dtype=np.int64)
        source = np.arange(len(rows)) if source is None else np.asarray(source, dtype=np.int64)
        order = np.argsort(rows, kind="stable")
        self.rows, self.take, self.total = rows[order], source[order], int(total)
        cut = np.flatnonzero(np.diff(self.rows) != 1) + 1
        first, last = np.r_[0, cut], np.r_[cut, len(rows)] - 1
        self.runs = np.column_stack([self.rows[first], self.rows[last] + 1]) if len(rows) else np.zeros((0, 2),
                                                                                                        np.int64)

    def pick(self, values):
        """This rank's values of its rows, in row order."""
        return np.ascontiguousarray(np.asarray(values)[self.take])


def _write_runs(ds, runs, values):
    """Write ``values`` (rows in order) into the rows ``runs`` of ``ds``: one write of a selection that is the
    union of the runs."""
    if not len(values):
        return
    import h5py
    tail = values.shape[1:]
    space = ds.id.get_space()
    space.select_none()
    zeros = (0,) * len(tail)
    for start, stop in runs:
        space.select_hyperslab((int(start),) + zeros, (int(stop - start),) + tail, op=h5py.h5s.SELECT_OR)
    ds.id.write(h5py.h5s.create_simple(values.shape), space, values)


class ParallelSeries:
    """A series (pfault.io.output.XdmfSeries) continued by every rank: ``NAME.h5`` in ``directory``, opened
    with the MPI-IO driver on ``comm``; ``rows`` {"Node": Rows, "Cell": Rows} says which rows of each kind of
    dataset this rank writes. Every method is collective."""

    def __init__(self, comm, directory, name, rows):
        self.comm = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
        self.name, self.rows = name, rows
        centers = sorted(rows)
        counts = self.comm.allreduce(np.array([len(rows[c].rows) for c in centers]))
        bad = {c: (int(n), rows[c].total) for c, n in zip(centers, counts) if n != rows[c].total}
        if bad:
            raise RuntimeError(f"{name}: the ranks' rows do not cover the datasets once (rows, total): {bad}")
        self.h5 = run_on_all(self.comm, self._open, os.path.join(directory, name + ".h5"))

    def _open(self, path):
        import h5py
        try:
            return h5py.File(path, "r+", driver="mpio", comm=self.comm, locking=False)
        except TypeError:
            return h5py.File(path, "r+", driver="mpio", comm=self.comm)

    def write_step(self, step, t, point_data=None, cell_data=None):
        """Write one step: arrays of this rank's values (local vertices or cells, as its Rows take them).
        Returns the step's XDMF entry (pfault.io.output.RunWriter.add_steps)."""
        data = [(center, key, self.rows[center].pick(value))
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
        """The step's group and datasets: [(dataset, runs of this rank, its values)]."""
        import h5py
        grp = self.h5.create_group(path)
        grp.attrs["step"], grp.attrs["time"] = step, t
        # no fill values: every row is written (fill values would be written first, by all ranks together)
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)
        datasets = []
        for center, key, value in data:
            rows = self.rows[center]
            ds = grp.create_dataset(key, shape=(rows.total,) + value.shape[1:], dtype=value.dtype, dcpl=dcpl)
            ds.attrs["center"] = center
            datasets.append((ds, rows.runs, value))
        return datasets

    @staticmethod
    def _fill(datasets):
        for ds, runs, value in datasets:
            _write_runs(ds, runs, value)

    def close(self):
        if self.h5 is not None:
            h5, self.h5 = self.h5, None
            run_on_all(self.comm, h5.close)

