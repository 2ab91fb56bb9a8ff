"""Displacement time series at stations (GNSS, levelling benchmarks, extensometers' heads): ``-pfault_stations
FILE``.

The station file is CSV with a header line naming its columns: ``name``, ``x``, ``y``, ``z`` (site coordinates,
m) and optionally ``side`` (``plus`` or ``minus``: the side a station on a fault takes, default minus; see
pfault.io.probes); other columns are ignored. Lines starting with ``#`` are comments. Columns are separated by
commas, or as spreadsheets save them, by tabs or by semicolons (then decimal commas are read too).

A run writes, at time 0 and after every converged step, the displacement relative to the initial state at each
station (P1 interpolation in its cell, pfault.io.probes):

- ``station_displacement.csv``: ``name,time_s,ux_m,uy_m,uz_m,side`` (time in seconds from the start of the
  scene, the unit of every pfault output; side: the fault side taken, empty for a station off the faults);
- ``station_displacement.h5``: the layout of PyLith's output at points: ``/stations`` (names),
  ``/geometry/vertices`` (n, 3) site coordinates, ``/time`` (nt, 1, 1) in s, ``/vertex_fields/displacement``
  (nt, n, 3) in m; and ``/side`` (n,) and ``/step`` (nt,) (the step number of each time).

A restart (-pfault_restart) takes the rows of the run it continues up to its checkpoint's step and goes on from
there: no row is missing or repeated.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError, run_on_root
from .output import open_h5, replace_text
from .observers import Observer
from .probes import SIDE_NAMES, Located, PointProbe, locate_points, mesh_to_site

CSV_NAME = "station_displacement.csv"
H5_NAME = "station_displacement.h5"
CSV_HEADER = "name,time_s,ux_m,uy_m,uz_m,side\n"
OPTION = "-pfault_stations"
COLUMNS_FIX = "its first line names the columns: name,x,y,z (and optionally side)"


@dataclass(frozen=True)
class Stations:
    names: list
    xyz: np.ndarray         # (n, 3) site coordinates
    plus: np.ndarray        # (n,) bool: a station on a fault takes its plus side


def read_stations(path: str) -> Stations:
    """The stations of the CSV file ``path`` (InputError, naming the file and the fix, on anything wrong)."""
    where = f"{OPTION} {path}"
    if not os.path.isfile(path):
        raise InputError(f"{where}: no such file; give a CSV file whose first line names the columns "
                         "name,x,y,z (and optionally side), then one station per line")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:     # a spreadsheet's byte-order mark is not text
            lines = fh.read().splitlines()
        first = next((line for line in lines if line.strip() and not line.lstrip().startswith("#")), "")
        # a spreadsheet set for decimal commas separates columns with semicolons (and its numbers may have
        # decimal commas there); tabs are allowed too
        delimiter = next((d for d in (";", "\t") if d in first and "," not in first), ",")
        rows = [(i + 1, r) for i, r in enumerate(csv.reader(lines, delimiter=delimiter))
                if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{where}: not a CSV text file ({exc}); {COLUMNS_FIX}") from None
    if not rows:
        raise InputError(f"{where}: empty; {COLUMNS_FIX}, then one station per line")
    header = [c.strip().lower() for c in rows[0][1]]
    missing = [c for c in ("name", "x", "y", "z") if c not in header]
    if missing:
        raise InputError(f"{where}: no column {', '.join(missing)} in its header line "
                         f"'{','.join(rows[0][1])}'; {COLUMNS_FIX}")
    col = {c: header.index(c) for c in header}
    names, xyz, plus = [], [], []
    for line, r in rows[1:]:
        r = r + [""] * (len(header) - len(r))
        name = r[col["name"]].strip()
        if not name:
            raise InputError(f"{where} line {line}: a station without a name; give each station a name")
        if name in names:
            raise InputError(f"{where} line {line}: station '{name}' appears twice; give each station its own name")
        try:
            x = [float(r[col[c]].replace(",", ".") if delimiter == ";" else r[col[c]]) for c in "xyz"]
        except ValueError:
            raise InputError(f"{where} line {line}: station '{name}': x, y, z must be numbers (m), got "
                             f"{', '.join(r[col[c]].strip() or '(empty)' for c in 'xyz')}") from None
        if not np.all(np.isfinite(x)):
            raise InputError(f"{where} line {line}: station '{name}': x, y, z must be finite numbers (m)")
        side = r[col["side"]].strip().lower() if "side" in col else ""
        if side not in ("", "plus", "minus"):
            raise InputError(f"{where} line {line}: station '{name}': side '{side}' is not plus or minus "
                             "(the side of a fault the station takes; leave it empty for minus)")
        names.append(name)
        xyz.append(x)
        plus.append(side == "plus")
    if not names:
        raise InputError(f"{where}: no stations after the header line; give one station per line")
    return Stations(names, np.array(xyz, dtype=np.float64), np.array(plus, dtype=bool))


def locate_stations(path: str, serial: Any, split: Any,
                    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> tuple[Stations, Located]:
    """Rank 0: read the station file and locate its stations in the serial mesh; InputError for stations outside
    the mesh (how many, which, and the mesh's extent)."""
    st = read_stations(path)
    located = locate_points(serial.points, serial.tets, mesh_to_site(st.xyz, origin, inverse=True),
                            None if split is None else split.vert_sides, None if split is None else split.cell_side,
                            st.plus)
    out = np.flatnonzero(located.cell < 0)
    if len(out):
        lo, hi = mesh_to_site(serial.points.min(axis=0), origin), mesh_to_site(serial.points.max(axis=0), origin)
        which = ", ".join(f"'{st.names[i]}' at ({', '.join(f'{v:g}' for v in st.xyz[i])})" for i in out[:3])
        more = f" and {len(out) - 3} more" if len(out) > 3 else ""
        raise InputError(f"{OPTION} {path}: {len(out)} station(s) outside the mesh: {which}{more}; the mesh spans "
                         f"x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g}, z {lo[2]:g}..{hi[2]:g} m (site "
                         "coordinates): move them inside or remove them")
    return st, located


def check_continuation(stations: Stations, run_dir: str) -> None:
    """A restart continues the station files of the run in ``run_dir``: it has them, for the same stations."""
    path = os.path.join(run_dir, H5_NAME)
    if not os.path.exists(path):
        raise InputError(f"{OPTION}: the run in -pfault_restart {run_dir} has no station output ({H5_NAME}); "
                         f"continue it without {OPTION}, or run the scene from the start with it")
    with open_h5(path, "r") as h5:
        names = [s.decode() for s in h5["stations"][()]]
        xyz = h5["geometry/vertices"][()]
    if names != list(stations.names) or not np.array_equal(xyz, stations.xyz):
        raise InputError(f"{OPTION}: the stations differ from those of the run in -pfault_restart {run_dir}; "
                         "give the station file that run had")


class StationSeries:
    """The station files of a run (rank 0): made whole at the start (the row of time 0, or the rows of the run a
    restart continues), then the rows of every recorded time appended in place: to the CSV, and to the HDF5
    file's datasets, resized (the file is closed after each time, so a reader sees every row written)."""

    def __init__(self, stations: Stations, side: np.ndarray) -> None:
        self.stations = stations
        self.side = [SIDE_NAMES[s] for s in side]

    def start(self, directory: str, restart_dir: str | None, restart_step: int | None) -> None:
        """A new run's files with the row of time 0; on a restart, those of the run it continues up to its
        checkpoint's step."""
        if restart_dir:
            steps, times, values = self._continue(restart_dir, int(restart_step or 0))
        else:
            steps, times, values = np.zeros(1, np.int64), np.zeros(1), np.zeros((1, len(self.side), 3))
        lines = [CSV_HEADER] + [self._rows(t, u) for t, u in zip(times, values)]
        replace_text(os.path.join(directory, CSV_NAME), "".join(lines))
        self._write_h5(directory, steps, times, values)

    def _continue(self, run_dir: str, last_step: int) -> tuple:
        check_continuation(self.stations, run_dir)
        with open_h5(os.path.join(run_dir, H5_NAME), "r") as h5:
            steps, times = h5["step"][()], h5["time"][:, 0, 0]
            values = h5["vertex_fields/displacement"][()]
        keep = steps <= last_step
        return steps[keep], times[keep], values[keep]

    def append(self, directory: str, step: int, t: float, u: np.ndarray) -> None:
        with open(os.path.join(directory, CSV_NAME), "a") as fh:
            fh.write(self._rows(t, u))
        with open_h5(os.path.join(directory, H5_NAME), "r+") as h5:
            k = len(h5["step"])
            for name in ("step", "time", "vertex_fields/displacement"):
                h5[name].resize(k + 1, axis=0)
            h5["step"][k], h5["time"][k] = int(step), float(t)
            h5["vertex_fields/displacement"][k] = u

    def _rows(self, t: float, u: np.ndarray) -> str:
        """CSV rows of one time (numbers as Python writes them: they read back to the same float)."""
        text = io.StringIO()
        csv.writer(text, lineterminator="\n").writerows(
            [name, repr(float(t)), *map(repr, v), side]
            for name, v, side in zip(self.stations.names, np.asarray(u).tolist(), self.side))
        return text.getvalue()

    def _write_h5(self, directory: str, steps: np.ndarray, times: np.ndarray, values: np.ndarray) -> None:
        """The HDF5 file with the given rows, written into a temporary file and renamed."""
        path = os.path.join(directory, H5_NAME)
        tmp = path + ".tmp"
        st, n = self.stations, len(self.stations.names)
        with open_h5(tmp, "w") as h5:
            width = max(len(name.encode()) for name in st.names)
            h5.create_dataset("stations", data=np.array([name.encode() for name in st.names], dtype=f"S{width}"))
            h5.create_dataset("side", data=np.array([side.encode() for side in self.side], dtype="S5"))
            h5.create_dataset("geometry/vertices", data=st.xyz).attrs["units"] = "m"
            t = h5.create_dataset("time", data=np.asarray(times, np.float64).reshape(-1, 1, 1), maxshape=(None, 1, 1))
            t.attrs["units"] = "s"
            h5.create_dataset("step", data=np.asarray(steps, np.int64), maxshape=(None,))
            d = h5.create_dataset("vertex_fields/displacement", data=np.asarray(values, np.float64).reshape(-1, n, 3),
                                  maxshape=(None, n, 3), chunks=(max(1, 4096 // n), n, 3))
            d.attrs["units"] = "m"
            d.attrs["vector_field_type"] = "vector"
            d.attrs["description"] = "displacement relative to the initial state (x, y, z)"
        os.replace(tmp, path)


class StationObserver(Observer):
    """Observer of the time loop (pfault.run): the stations' displacement at time 0 (or the rows of the run a
    restart continues) and after every converged step."""

    def __init__(self, output: Any, stations: Stations | None, located: Located) -> None:
        m = output.model
        self.output, self.comm = output, m.comm
        self.probe = PointProbe(m.comm, m.mesh, m.dofmap, located)
        self.series = StationSeries(stations, located.side) if m.comm.rank == 0 else None
        self.started = False

    def step_done(self, result: Any) -> None:
        out = self.output
        if not self.started:
            run_on_root(self.comm, lambda: self.series.start(out.writer.dir, out.restart_dir, out.restart_step))
            self.started = True
        if not result.record.converged:
            return
        u = self.probe.values(result.u_rel)
        run_on_root(self.comm, lambda: self.series.append(out.writer.dir, result.step, result.t, u))
