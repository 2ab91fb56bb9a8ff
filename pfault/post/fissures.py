"""Fissures that formed: the broken faces of a run's candidate surfaces, read from its directory, measured and drawn.

A fault with a tensile strength (``-pfault_fault_<name>_tensile_strength``) stays glued until its strength is
exceeded; fault.h5 then holds, in each step group, ``broken`` (0/1 per face: broken at or before that step) and
``break_time`` (s, NaN while intact), and summary.json's ``faults`` {NAME: {``broken_area_m2``, ``broken_depth_m``,
``broken_length_m``, ``first_break_time_s``}}. A run written without them (every run before fault breaking, and every
run whose faults have no strength) has no fissure figure, and its hazard map is drawn as before.

- ``fissure_break.png`` (``fissure_figure``): for each fault with broken faces, its surface in fault-plane
  coordinates coloured by the year each face broke, intact faces grey, with the fissure's depth below the land
  surface, its length along the land-surface trace, its broken area, the largest opening of its broken faces,
  the time of the first break and the time the fissure reached the land surface; below them, the fissures' depth,
  surface length and largest opening against time (``history``);
- on ``hazard_map.png`` (pfault.post.figures.hazard_figure, ``draw_surface_traces``): the traces on the land
  surface of the fissures that reached it: the edges of broken faces whose two vertices lie on the land surface.

The land surface is that of surface.h5 (``-pfault_ground_surface``: a vertex of the fault is on it when a point of
the surface has its coordinates), else the plane z = max z. Depths are measured from the highest point of the
land surface (flat land surfaces, as the built-in scenes have). Rank 0, from the files; NumPy, h5py, matplotlib.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..io.output import open_h5
from ..units import YEAR
from .meshes import face_geometry, plane_axes
from .plots import pyplot, save, scene_name, title_time
from .rundir import read_options, read_summary

FIGURE = "fissure_break.png"
# summary.json's per-fault keys of the fissure (written by the run that broke the faces)
SUMMARY_KEYS = ("broken_area_m2", "broken_depth_m", "broken_length_m", "first_break_time_s")


@dataclass
class Breaks:
    """The fault faces at one output time of fault.h5: mesh (serial points, the minus-side vertices), the fault
    index of each face, whether it is broken, when it broke (s, NaN while intact) and its opening (m)."""
    points: np.ndarray
    faces: np.ndarray
    fault: np.ndarray
    broken: np.ndarray
    break_time: np.ndarray
    opening: np.ndarray
    time: float
    index: int          # of the output time among fault.h5's steps
    num_steps: int


def read_breaks(run_dir: str, step: int = -1, time: float | None = None) -> Breaks | None:
    """The faces broken in the run by output time ``step`` of fault.h5 (or, given ``time``, at the last output time
    not after it): a pre-existing fault's faces, broken from the start and without a break time, are not fissures
    that formed. None when the run has no fault.h5 or that time has no ``broken`` dataset (a run written without
    them)."""
    path = os.path.join(run_dir, "fault.h5")
    if not os.path.exists(path):
        return None
    with open_h5(path, "r") as f:
        groups = [f["steps"][k] for k in sorted(f.get("steps", {}))]
        if not groups:
            return None
        times = np.array([float(g.attrs["time"]) for g in groups])
        if time is not None:
            step = max(int(np.count_nonzero(times <= time + 1e-9 * max(abs(time), 1.0))) - 1, 0)
        if not -len(groups) <= step < len(groups):
            raise IndexError(f"{path}: output time {step} out of range ({len(groups)} times written)")
        g = groups[step]
        if "broken" not in g or "break_time" not in g:
            return None
        n = len(f["mesh/cells"])
        opening = g["opening"][...] if "opening" in g else np.zeros(n)
        fault = g["fault"][...] if "fault" in g else np.zeros(n)
        when = g["break_time"][...].astype(float)
        formed = (g["broken"][...] != 0) & np.isfinite(when)     # a pre-existing fault's faces have no break time
        return Breaks(f["mesh/points"][...], f["mesh/cells"][...].astype(np.int64), fault.astype(np.int64),
                      formed, when, opening, float(g.attrs["time"]),
                      step % len(groups), len(groups))


def on_land_surface(run_dir: str, points: np.ndarray) -> np.ndarray:
    """Mask of the ``points`` that lie on the land surface: those with the coordinates of a point of surface.h5,
    else those on the plane z = max z."""
    path = os.path.join(run_dir, "surface.h5")
    if os.path.exists(path):
        with open_h5(path, "r") as f:
            surf = f["mesh/points"][...]
        keys = np.concatenate([surf, points])
        _, inv = np.unique(keys, axis=0, return_inverse=True)
        inv = inv.ravel()
        return np.isin(inv[len(surf):], inv[:len(surf)])
    z = points[:, 2]
    return np.abs(z - z.max()) <= 1e-9 * max(float(np.ptp(points, axis=0).max()), 1.0)


def surface_edges(faces: np.ndarray, broken: np.ndarray, on_surface: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges (k, 2) of broken faces whose two vertices are on the land surface, and the face of each."""
    edges = faces[:, [[0, 1], [1, 2], [2, 0]]]                       # (n, 3, 2)
    hit = on_surface[edges].all(axis=2) & broken[:, None]
    return edges[hit], np.nonzero(hit)[0]


def fissure_measures(b: Breaks, on_surface: np.ndarray, names: list[str]) -> dict[str, dict[str, float]]:
    """Per fault with broken faces (by name): broken area (m^2), depth of its deepest broken vertex below the land
    surface (m), length of its trace on the land surface (m), largest opening of a broken face (m), time of the
    first break and time it reached the land surface (s; NaN when it has not)."""
    _, area, _ = face_geometry(b.points, b.faces)
    ztop = float(b.points[on_surface, 2].max()) if on_surface.any() else float(b.points[:, 2].max())
    edges, edge_face = surface_edges(b.faces, b.broken, on_surface)
    seg = np.linalg.norm(b.points[edges[:, 1]] - b.points[edges[:, 0]], axis=1)
    out: dict[str, dict[str, float]] = {}
    for k in np.unique(b.fault[b.broken]):
        mine = b.broken & (b.fault == k)
        at_top = b.fault[edge_face] == k
        out[names[k] if k < len(names) else f"fault {k}"] = {
            "broken_area_m2": float(area[mine].sum()),
            "broken_depth_m": float(ztop - b.points[b.faces[mine], 2].min()),
            "broken_length_m": float(seg[at_top].sum()),
            "max_opening_m": float(np.max(b.opening[mine], initial=0.0)),
            "first_break_time_s": float(np.nanmin(b.break_time[mine])),
            "surface_break_time_s": float(np.nanmin(b.break_time[edge_face[at_top]])) if at_top.any() else np.nan}
    return out


def fault_names(run_dir: str) -> list[str]:
    """The faults' names in the order of their index (summary.json's ``faults``, else options.txt's
    ``-pfault_faults``)."""
    try:
        names = list((read_summary(run_dir) or {}).get("faults", {}))
    except (OSError, ValueError):
        names = []
    if not names:
        names = [n.strip() for n in read_options(run_dir).get("pfault_faults", "").split(",") if n.strip()]
    return names


def measures(run_dir: str, b: Breaks) -> dict[str, dict[str, float]]:
    """``fissure_measures`` of a run's faces; at the last output time, summary.json's figures of a fault take the
    place of the measured ones (the figure then says what summary.json says)."""
    names = fault_names(run_dir)
    out = fissure_measures(b, on_land_surface(run_dir, b.points), names)
    if b.index == b.num_steps - 1:
        try:
            faults = (read_summary(run_dir) or {}).get("faults", {})
        except (OSError, ValueError):
            faults = {}
        for name, m in out.items():
            m.update({k: float(faults[name][k]) for k in SUMMARY_KEYS if faults.get(name, {}).get(k) is not None})
    return out


def _years(t: float) -> str:
    return "not yet" if not np.isfinite(t) else f"t = {t / YEAR:.3g} years"


def _label(m: dict[str, float]) -> str:
    return (f"depth {m['broken_depth_m']:.3g} m below the land surface, {m['broken_area_m2']:.4g} m$^2$ broken\n"
            f"length along the surface trace {m['broken_length_m']:.4g} m, "
            f"largest opening {100.0 * m['max_opening_m']:.3g} cm\n"
            f"first break at {_years(m['first_break_time_s'])}, "
            f"at the land surface: {_years(m['surface_break_time_s'])}")


def _fault_panel(fig: Any, ax: Any, b: Breaks, mine: np.ndarray, name: str, m: dict[str, float]) -> None:
    """One fault: its faces in its plane's coordinates, broken ones coloured by the year they broke, intact grey."""
    from matplotlib.colors import ListedColormap
    from matplotlib.tri import Triangulation
    faces = b.faces[mine]
    normals, _, _ = face_geometry(b.points, faces)
    axis, (ia, ib) = plane_axes(normals)
    tri = Triangulation(b.points[:, ia], b.points[:, ib], faces)
    broken = b.broken[mine]
    if (~broken).any():
        tri.set_mask(broken)
        ax.tripcolor(tri, facecolors=np.zeros(len(faces)), cmap=ListedColormap(["0.82"]), edgecolors="none")
    years = np.where(broken, b.break_time[mine], 0.0) / YEAR
    tri = Triangulation(b.points[:, ia], b.points[:, ib], faces, mask=~broken)
    lo, hi = float(years[broken].min()), float(years[broken].max())
    pc = ax.tripcolor(tri, facecolors=years, cmap="plasma_r", vmin=lo, vmax=max(hi, lo + 1e-9), edgecolors="none")
    fig.colorbar(pc, ax=ax, pad=0.01).set_label("year the face broke")
    names = "xyz"
    plane = float(np.median(b.points[faces, axis]))
    ax.set_title(f"{name}: {int(broken.sum())} of {len(faces)} faces broken (grey: intact), "
                 f"{title_time(b.time)}", fontsize=10)
    ax.text(0.01, 0.03, _label(m), transform=ax.transAxes, fontsize=8.5, va="bottom",
            bbox=dict(boxstyle="round", fc="white", alpha=0.85))
    ax.set_xlabel(f"{names[ia]} (m), along the fault plane {names[axis]} = {plane:g} m")
    ax.set_ylabel(f"{names[ib]} (m, stretched)")
    ax.set_xlim(b.points[faces, ia].min(), b.points[faces, ia].max())
    ax.set_ylim(b.points[faces, ib].min(), b.points[faces, ib].max())


def history(run_dir: str, last: int = -1) -> dict[str, dict[str, np.ndarray]]:
    """Per fault that has broken by output time ``last``: its ``fissure_measures`` at every output time up to it
    ({"time_s": (k,), "broken_depth_m": (k,), ...}; zero before its first break)."""
    first = read_breaks(run_dir, 0)
    if first is None:
        return {}
    names = fault_names(run_dir)
    on_surface = on_land_surface(run_dir, first.points)
    rows = []
    for k in range(last % first.num_steps + 1):
        b = first if k == 0 else read_breaks(run_dir, k)
        rows.append((b.time, fissure_measures(b, on_surface, names)))
    out: dict[str, dict[str, np.ndarray]] = {}
    for name in rows[-1][1]:
        keys = rows[-1][1][name].keys()
        out[name] = {"time_s": np.array([t for t, _ in rows])}
        out[name].update({key: np.array([m[name][key] if name in m else 0.0 for _, m in rows]) for key in keys})
    return out


def _history_panels(fig: Any, spec: Any, hist: dict[str, dict[str, np.ndarray]]) -> None:
    """The fissures' depth, length along the land surface and largest opening against time."""
    panels = (("broken_depth_m", 1.0, "depth below the land surface (m)"),
              ("broken_length_m", 1.0, "length along the land surface (m)"),
              ("max_opening_m", 100.0, "largest opening of a broken face (cm)"))
    grid = spec.subgridspec(1, len(panels))
    for i, (key, scale, label) in enumerate(panels):
        ax = fig.add_subplot(grid[0, i])
        for name, h in hist.items():
            ax.plot(h["time_s"] / YEAR, scale * h[key], "o-", ms=3, label=name)
        ax.set_xlabel("time (years)")
        ax.set_title(label, fontsize=10)
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
    if len(hist) > 1:
        ax.legend(fontsize=8)


def fissure_figure(run_dir: str, out: str | None = None, step: int = -1) -> str | None:
    """``fissure_break.png`` at one output time: a map of each fault with broken faces, coloured by when each
    face broke, and the fissures' depth, surface length and opening against time up to it; returns its path, or
    None when no face is broken (or the run has no ``broken`` dataset)."""
    b = read_breaks(run_dir, step)
    if b is None or not b.broken.any():
        return None
    plt = pyplot()
    names = fault_names(run_dir)
    m = measures(run_dir, b)
    ids = [int(k) for k in np.unique(b.fault[b.broken])]
    fig = plt.figure(figsize=(11, 3.6 * len(ids) + 3.4), constrained_layout=True)
    grid = fig.add_gridspec(len(ids) + 1, 1, height_ratios=[3.6] * len(ids) + [2.8])
    for row, k in enumerate(ids):
        name = names[k] if k < len(names) else f"fault {k}"
        _fault_panel(fig, fig.add_subplot(grid[row, 0]), b, b.fault == k, name, m[name])
    _history_panels(fig, grid[len(ids), 0], history(run_dir, b.index))
    fig.suptitle(f"{scene_name(run_dir)}: fissures formed (broken faces of the candidate surfaces)")
    return save(fig, out or os.path.join(run_dir, FIGURE))


def draw_surface_traces(ax: Any, run_dir: str, t: float, km: float) -> float:
    """On a map of the land surface (x, y in km): the traces of the fissures that reached it at the output time
    ``t``, labelled with their length and when they reached it; returns the length (m, 0 when none did or the run
    has no ``broken`` dataset)."""
    from matplotlib.collections import LineCollection
    b = read_breaks(run_dir, time=t)
    if b is None or not b.broken.any():
        return 0.0
    edges, face = surface_edges(b.faces, b.broken, on_land_surface(run_dir, b.points))
    if not len(edges):
        return 0.0
    xy = b.points[edges][:, :, :2]
    length = float(np.linalg.norm(xy[:, 1] - xy[:, 0], axis=1).sum())
    since = float(np.nanmin(b.break_time[face]))
    ax.add_collection(LineCollection(xy * km, colors="white", linewidths=4.0))
    ax.add_collection(LineCollection(xy * km, colors="crimson", linewidths=2.2,
                                     label=f"fissure at the land surface: {length:.4g} m (since {_years(since)})"))
    return length
