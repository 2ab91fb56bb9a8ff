"""Each compressible layer's time series at the stations (``-pfault_stations``): ``station_soil.csv``.

One row per station, layer and recorded time (time 0, then every converged step): ``name,time_s,step,layer,
critical_head_m,head_margin_m,compaction_elastic_m,compaction_inelastic_m``. Along the vertical column under the
station (pfault.soils.columns): the highest critical head of the layer's cells (relative to the initial heads) and
their smallest margin to it (the further drawdown before part of the layer compacts inelastically again), and the
layer's elastic and inelastic compaction (m; the inelastic one stays when the heads recover). A layer the column does
not cross has empty fields. A restart takes the rows of the run it continues up to its checkpoint's step.
"""

from __future__ import annotations

import csv
import io
import os
from typing import Any

import numpy as np

from ..errors import InputError, run_on_root
from ..io.observers import Observer
from ..io.output import replace_text
from ..io.probes import mesh_to_site

NAME = "station_soil.csv"
HEADER = "name,time_s,step,layer,critical_head_m,head_margin_m,compaction_elastic_m,compaction_inelastic_m\n"
COLUMNS = ("critical_head", "head_margin", "compaction_elastic", "compaction_inelastic")


def rows(names: list, layers: tuple, step: int, t: float, values: dict) -> str:
    """The CSV rows of one time (rank 0): ``values`` per station and layer (pfault.soils.columns.SoilColumns.layers)."""
    text = io.StringIO()
    out = csv.writer(text, lineterminator="\n")
    for i, name in enumerate(names):
        for k, layer in enumerate(layers):
            cells = [values[c][i, k] for c in COLUMNS]
            out.writerow([name, repr(float(t)), int(step), layer, *("" if np.isnan(v) else repr(float(v))
                                                                   for v in cells)])
    return text.getvalue()


def earlier_rows(run_dir: str, last_step: int) -> str:
    """The rows of the run in ``run_dir`` up to ``last_step`` (rank 0); InputError if it has none."""
    path = os.path.join(run_dir, NAME)
    if not os.path.isfile(path):
        raise InputError(f"-pfault_stations: the run in -pfault_restart {run_dir} has no {NAME}; continue it without "
                         "-pfault_stations, or run the scene from the start with it")
    with open(path, newline="") as fh:
        lines = fh.read().splitlines()[1:]
    return "".join(line + "\n" for line in lines if int(line.split(",")[2]) <= last_step)


class SoilStationObserver(Observer):
    """station_soil.csv of a run: the columns of the term ``k`` of the equations (``columns``) under the stations
    (``names`` on rank 0, their site coordinates ``xyz``); the rows of time 0 are measured when it is made (the
    initial state). Collective."""

    def __init__(self, output: Any, k: int, columns: Any, names: list | None) -> None:
        self.output, self.k, self.columns, self.names = output, k, columns, names
        m = output.model
        self.comm, self.layers = m.comm, columns.term.soil.names
        eq, state = m.equations, output.state
        rest = m.equations.terms[k].at_rest(eq.loads.term_loads[k])
        self.first = self._rows(0, 0.0, eq.local_array(state.u_ref), rest, state.histories[k])
        self.started = False

    def _rows(self, step: int, t: float, x_loc: np.ndarray, load: Any, history: Any) -> str | None:
        values = self.columns.layers(x_loc, load, history)
        return None if values is None else rows(self.names, self.layers, step, t, values)

    def step_done(self, result: Any) -> None:
        out = self.output
        if not self.started:
            def start() -> None:
                earlier = (earlier_rows(out.restart_dir, int(out.restart_step or 0)) if out.restart_dir
                           else self.first)
                replace_text(os.path.join(out.writer.dir, NAME), HEADER + earlier)
            run_on_root(self.comm, start)
            self.started = True
        if not result.record.converged:
            return
        eq, state = out.model.equations, out.state
        text = self._rows(result.step, result.t, eq.local_array(state.u), eq.loads.term_loads[self.k],
                          state.histories[self.k])

        def append() -> None:
            with open(os.path.join(out.writer.dir, NAME), "a") as fh:
                fh.write(text)
        run_on_root(self.comm, append)


def soil_station_observers(output: Any, stations: Any, origin: tuple) -> list:
    """The observers of the terms that measure along columns under the stations (``stations``: rank 0's
    pfault.io.stations.Stations, None elsewhere; ``origin``: site = mesh + origin). Collective."""
    m = output.model
    mpi = m.comm.tompi4py()
    xyz = mpi.bcast(None if stations is None else mesh_to_site(stations.xyz, origin, inverse=True), root=0)
    out = []
    for k, term in enumerate(m.equations.terms):
        columns = term.columns(xyz[:, :2], m.mesh)
        if columns is not None:
            out.append(SoilStationObserver(output, k, columns, None if stations is None else stations.names))
    return out
