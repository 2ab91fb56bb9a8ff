"""Reading a run directory: the files pfault.io.output, pfault.io.steps and pfault.io.stations write, for the
figures, the GIS layers, the tools that run pfault many times, the studies and the tests.

- ``read_summary``: summary.json (None when the run wrote none); ``read_options``: options.txt ({name: value}, the
  parser of pfault.io.output); ``read_materials``: materials.json;
- ``read_fields``, ``read_fault``, ``read_surface``: one output time of the XDMF series (meshio), as a ``Snapshot``;
  ``read_surface_steps``: every output time of surface.h5;
- ``read_station_series``: each station's displacement series from station_displacement.csv.

Rank 0 or any process: no PETSc, no MPI; meshio when an XDMF series is read.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..io import output
from ..io.stations import CSV_NAME

SUMMARY = "summary.json"


@dataclass
class Snapshot:
    """One output time of fields.xdmf (tetrahedra) or fault.xdmf (triangles)."""
    points: np.ndarray
    cells: np.ndarray
    time: float
    point_data: dict = field(default_factory=dict)
    cell_data: dict = field(default_factory=dict)
    num_steps: int = 0


def read_summary(run_dir: str) -> dict[str, Any] | None:
    """summary.json of a run directory (None if the run wrote none)."""
    path = os.path.join(str(run_dir), SUMMARY)
    if not os.path.exists(path):
        return None
    with open(path) as fh:
        return json.load(fh)


def read_options(run_dir: str) -> dict[str, str]:
    """The resolved options of a run (options.txt) as {name without '-': value string ('' for flags)}; {} when the
    run wrote none."""
    if not os.path.exists(os.path.join(run_dir, output.OPTIONS)):
        return {}
    return output.read_options(run_dir)


def read_materials(run_dir: str) -> dict[int, str]:
    """{material id: name} from materials.json."""
    with open(os.path.join(run_dir, "materials.json")) as fh:
        return {int(k): v for k, v in json.load(fh).items()}


def _read_series(path, step, cell_type):
    import meshio
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, blocks = reader.read_points_cells()
        n = reader.num_steps
        if not -n <= step < n:
            raise IndexError(f"{path}: output time {step} out of range ({n} times written)")
        t, point_data, cell_data = reader.read_data(step % n)
    cells = np.concatenate([b.data for b in blocks if b.type == cell_type])
    cell_data = {k: np.concatenate(v) for k, v in cell_data.items()}
    return Snapshot(np.asarray(points), np.asarray(cells, dtype=np.int64), float(t),
                    {k: np.asarray(v) for k, v in point_data.items()}, cell_data, n)


def read_fields(run_dir: str, step: int = -1) -> Snapshot:
    """Mesh (a split fault vertex appears once per piece of its star; each cell uses its pieces' copies) and
    fields at one time:
    point data ``displacement`` (m, relative to the initial state), ``head_change`` (m, flow scenes); cell data
    ``material``, ``pore_pressure_change`` (Pa), ``stress`` (Pa)."""
    return _read_series(os.path.join(run_dir, "fields.xdmf"), step, "tetra")


def read_fault(run_dir: str, step: int = -1) -> Snapshot:
    """Fault triangles (on the serial points, i.e. the minus-side vertices) and per-face fields at one time:
    ``opening`` (m), ``slip`` (m, 3 components), ``slip_magnitude`` (m), ``traction_normal`` (Pa),
    ``traction_shear`` (Pa), ``state`` (stick/slip/open code), ``slid`` (1: slipping or open at the end of a
    completed step, now or before), ``fault`` (fault index)."""
    return _read_series(os.path.join(run_dir, "fault.xdmf"), step, "triangle")


def has_fault(run_dir: str) -> bool:
    return os.path.exists(os.path.join(run_dir, "fault.xdmf"))


def read_surface(run_dir: str, step: int = -1) -> Snapshot:
    """Land-surface triangles and fields at one time: point data ``displacement`` (m), cell data
    ``horizontal_strain``, ``angular_distortion`` (pfault.hazard)."""
    return _read_series(os.path.join(run_dir, "surface.xdmf"), step, "triangle")


def has_surface(run_dir: str) -> bool:
    return os.path.exists(os.path.join(run_dir, "surface.xdmf"))


def read_surface_steps(run_dir: str) -> tuple[np.ndarray, np.ndarray, list]:
    """surface.h5: its points (mesh coordinates), triangles, and per output time (step, time, displacement,
    horizontal strain, angular distortion)."""
    with output.open_h5(os.path.join(run_dir, "surface.h5"), "r") as f:
        points, tris = f["mesh/points"][...], f["mesh/cells"][...].astype(np.int64)
        steps = []
        for key in sorted(f["steps"]):
            g = f["steps"][key]
            steps.append((int(g.attrs["step"]), float(g.attrs["time"]), g["displacement"][...],
                          g["horizontal_strain"][...], g["angular_distortion"][...]))
    return points, tris, steps


@dataclass(frozen=True)
class StationSeries:
    """A station's displacement series as station_displacement.csv holds it."""
    time: np.ndarray        # (nt,) s
    u: np.ndarray           # (nt, 3) m: ux, uy, uz relative to the initial state

    def at(self, t: Sequence[float] | np.ndarray) -> np.ndarray:
        """(len(t), 3): linear in time between the run's output times (t within them)."""
        t = np.asarray(t, dtype=np.float64)
        return np.stack([np.interp(t, self.time, self.u[:, k]) for k in range(3)], axis=1)


def read_station_series(output_dir: str) -> dict[str, StationSeries]:
    """The series of every station of a run, from its station_displacement.csv (a restart's rows in time
    order; a time written twice keeps its last row)."""
    rows: dict[str, dict[float, list[float]]] = {}
    with open(os.path.join(output_dir, CSV_NAME), newline="") as fh:
        for r in csv.DictReader(fh):
            rows.setdefault(r["name"], {})[float(r["time_s"])] = [float(r["ux_m"]), float(r["uy_m"]),
                                                                   float(r["uz_m"])]
    series = {}
    for name, by_time in rows.items():
        t = np.array(sorted(by_time))
        series[name] = StationSeries(t, np.array([by_time[x] for x in t], dtype=np.float64))
    return series
