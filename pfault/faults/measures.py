"""What a step's record, fault.h5 and summary.json report of the faults, measured from a state (collective where
it says so).

The jumps reported are the face-mean jumps (with the bubbles' part) relative to the initial state; a closed face's
opening and a stuck face's slip increment are zero to the solver's tolerance and are not counted in the maxima
(fault.h5 has every face's jump). The integrals over each fault converge under refinement where a largest value
may not (it sits at a singular point: a fault's tip, its foot on a fixed boundary).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from .contact import OPEN, SLIP, STATE_NAMES, STICK




@dataclass(frozen=True)
class FaultFigures:
    """One fault at a step: its faces stuck, slipping and open, its largest opening of an open face and slip of a
    face that has slid (m), its integrals (slip potency and open volume, m^3; slipping and open areas, m^2) and
    its broken part (faces, area m^2, depth m, trace length on the land surface m, first break time s or None)."""
    faces_stuck: int
    faces_slipping: int
    faces_open: int
    max_opening_m: float
    max_slip_m: float
    slip_potency_m3: float
    open_volume_m3: float
    slipping_area_m2: float
    open_area_m2: float
    faces_broken: int
    broken_area_m2: float
    broken_depth_m: float
    broken_length_m: float
    first_break_time_s: float | None


@dataclass(frozen=True)
class FaultMeasures:
    """The faults at a step: each fault's figures (by name) and the largest opening and slip over them (m)."""
    faults: dict
    max_fault_opening_m: float
    max_fault_slip_m: float

    def as_json(self) -> dict:
        return {"max_fault_opening_m": self.max_fault_opening_m, "max_fault_slip_m": self.max_fault_slip_m,
                "faults": {name: asdict(f) for name, f in self.faults.items()}}


def state_counts(mpi: Any, states: np.ndarray) -> dict:
    """{stick, slip, open: faces on all ranks} (collective)."""
    c = mpi.allreduce(np.bincount(states, minlength=3), op=MPI.SUM)
    return {name: int(c[i]) for i, name in enumerate(STATE_NAMES)}


def broken_figures(faces: Any, n_faults: int, ground: np.ndarray, coords: np.ndarray, broken: np.ndarray,
                   break_time: np.ndarray) -> np.ndarray:
    """Per fault (rows in the order of the scene's faults): faces broken, their area (m^2), the depth of the
    deepest broken point below the land surface (m: below its highest point; the built-in scenes' land surfaces
    are flat), the length of the broken part's trace on the land surface (m: the broken faces' edges whose two
    vertices are on it) and the first break time (s, NaN if none broke in the run). ``ground``: the local
    vertices on the land surface; ``coords``: the local vertices'. Collective."""
    mpi = faces.mpi
    top = mpi.allreduce(float(np.max(coords[ground, 2], initial=-np.inf)), op=MPI.MAX)
    xyz = coords[faces.verts]                                          # (nf, 3 vertices, 3)
    depth = np.where(broken, top - xyz[:, :, 2].min(axis=1), 0.0) if np.isfinite(top) else np.zeros(len(broken))
    on = ground[faces.verts]
    edges = [(0, 1), (1, 2), (2, 0)]
    trace = sum(np.where(on[:, a] & on[:, b], np.linalg.norm(xyz[:, a] - xyz[:, b], axis=1), 0.0)
                for a, b in edges) if len(broken) else np.zeros(0)
    sums = np.zeros((n_faults, 3))
    np.add.at(sums, faces.fault, np.column_stack([broken, faces.area * broken, trace * broken]))
    mx = np.full((n_faults, 2), -np.inf)
    np.fmax.at(mx, faces.fault, np.column_stack([depth, -np.where(broken, break_time, np.nan)]))   # NaN: none
    mpi.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    mpi.Allreduce(MPI.IN_PLACE, mx, op=MPI.MAX)
    first = np.where(np.isfinite(mx[:, 1]), -mx[:, 1], np.nan)
    return np.column_stack([sums[:, 0], sums[:, 1], np.maximum(mx[:, 0], 0.0), sums[:, 2], first])


def fault_figures(faces: Any, names: list, states: np.ndarray, slid: np.ndarray, gl: np.ndarray,
                  broken: np.ndarray) -> FaultMeasures:
    """Per fault (by name): how many faces are stuck, slipping and open (``states``: each owned face's, as
    reported), the largest opening of its open faces and the largest slip of its faces that have slid (``slid``),
    0 where there are none; the largest of these over the faults; and the integrals over each fault: the slip
    potency (m^3, the area integral of the slip of the faces that have slid), the open volume (m^3, of the opening
    of the open faces) and the slipping and open areas (m^2). ``gl``: the faces' jumps (local frame) relative to
    the initial state; ``broken``: each fault's ``broken_figures`` row. Collective."""
    opening = np.where(states == OPEN, gl[:, 0], 0.0)
    slip = np.where(slid, np.linalg.norm(gl[:, 1:], axis=1), 0.0)
    counts = np.zeros((len(names), 3), dtype=np.int64)
    np.add.at(counts, (faces.fault, states), 1)
    largest = np.zeros((len(names), 2))
    np.maximum.at(largest, faces.fault, np.column_stack([opening, slip]))
    a = faces.area
    integrals = np.zeros((len(names), 4))
    np.add.at(integrals, faces.fault, np.column_stack([a * slip, a * opening, a * (states == SLIP),
                                                       a * (states == OPEN)]))
    mpi = faces.mpi
    mpi.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
    mpi.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
    mpi.Allreduce(MPI.IN_PLACE, integrals, op=MPI.SUM)
    per = {name: FaultFigures(int(c[STICK]), int(c[SLIP]), int(c[OPEN]), float(m[0]), float(m[1]),
                              *(float(v) for v in i), int(b[0]), float(b[1]), float(b[2]), float(b[3]),
                              float(b[4]) if np.isfinite(b[4]) else None)
           for name, c, m, i, b in zip(names, counts, largest, integrals, broken)}
    return FaultMeasures(per, float(largest[:, 0].max(initial=0.0)), float(largest[:, 1].max(initial=0.0)))


def face_fields(term: Any, x_total: np.ndarray, x_rel: np.ndarray, load: Any, history: Any, slid: np.ndarray
                ) -> dict:
    """fault.h5's fields per owned face: tractions from the total state, jumps relative to the initial state
    (every face's, as computed), its state (stick 0, slip 1, open 2) and whether it has slid (``slid``: its slip
    is in the reported maxima), whether it is broken and when it broke (s, NaN while intact and on a
    pre-existing fault), and its effective normal traction."""
    faces = term.faces
    t = term.tractions(x_total)
    tg = np.einsum("nji,nj->ni", faces.R, t)
    state = term.configuration(x_total, load, history, exact=False)
    g, gl = term.mean_jumps(x_rel, term.tractions(x_rel), load)
    return {"traction_normal": t[:, 0], "traction_shear": tg - t[:, :1] * faces.normal,
            "opening": gl[:, 0], "slip": g - gl[:, :1] * faces.normal,
            "slip_magnitude": np.linalg.norm(gl[:, 1:], axis=1), "state": np.asarray(state, dtype=np.int64),
            "slid": np.asarray(slid, dtype=np.int64), "broken": np.asarray(history.broken, dtype=np.int64),
            "break_time": np.asarray(history.break_time, dtype=float),
            "traction_normal_effective": load.effective(t)[:, 0]}


def beside_height(faces: Any, coords: np.ndarray, cells: np.ndarray, n_faults: int) -> list:
    """Per fault, the mean height of the cells on both sides of its faces over them (3 x volume / face area,
    weighted by the face's area: the distance the P1 displacement spreads a jump over, the resolution of the
    fault's answer; m). Collective."""
    x = coords[cells[faces.sides.cell]]                                # (nf, 2, 4, 3)
    e = x[:, :, 1:] - x[:, :, :1]
    volume = np.abs(np.einsum("nsi,nsi->ns", e[:, :, 0], np.cross(e[:, :, 1], e[:, :, 2]))) / 6.0
    sums = np.zeros((n_faults, 2))
    np.add.at(sums, faces.fault, np.column_stack([1.5 * volume.sum(axis=1), faces.area]))
    sums = faces.mpi.allreduce(sums)
    return [float(h / a) if a > 0 else 0.0 for h, a in sums]


def fault_summary(faces: Any, names: list, coords: np.ndarray, cells: np.ndarray, steps: list) -> dict:
    """summary.json's ``faults``: per fault (by name) its faces, the mean height of the cells beside it, the
    largest opening of an open face and slip of a face that has slid over the step records ``steps`` (0 where none
    did), and at the last of them its faces stuck, slipping, open and broken, its integrals and its broken part's
    figures (``fault_figures``). Collective."""
    counts = faces.mpi.allreduce(np.bincount(faces.fault, minlength=len(names)))
    height = beside_height(faces, coords, cells, len(names))
    out = {}
    for k, name in enumerate(names):
        per = [r["faults"][name] for r in steps if "faults" in r]
        last = per[-1] if per else {}
        out[name] = {"faces": int(counts[k]), "beside_cell_height_m": height[k],
                     "max_opening_m": max([p["max_opening_m"] for p in per], default=0.0),
                     "max_slip_m": max([p["max_slip_m"] for p in per], default=0.0),
                     **dict.fromkeys(("faces_stuck", "faces_slipping", "faces_open", "faces_broken", "broken_area_m2",
                                      "broken_depth_m", "broken_length_m"), 0),
                     "first_break_time_s": None,
                     **{key: v for key, v in last.items() if key not in ("max_opening_m", "max_slip_m")}}
    return {"faults": out}
