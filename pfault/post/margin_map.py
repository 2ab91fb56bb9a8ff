"""``fault_margins.png``: each fault's margins to failure over its plane at an output time, from fault.h5's
``margin_drawdown_m`` (m of further drawdown of the loaded materials at which a face slips, opens or breaks; 0 on
faces failed now, inf where no further drawdown fails it) and ``margin_mode``.

The faces are coloured by band: failed now, within the first of the run's thresholds (summary.json's
``area_within_m2`` keys, ``-pfault_margin_thresholds``; default 1, 5, 10 m), between the next ones, beyond the
last, and grey where no further drawdown fails them; the face with the smallest margin of each fault is starred
and its margin, mode and position written above, with the areas within each threshold. Each fault is drawn in its
plane: the distance along its strike against z (a horizontal fault in x, y). Rank 0, from the files; NumPy, h5py,
matplotlib.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..io.output import open_h5
from .fissures import fault_names
from .meshes import face_geometry
from .plots import pyplot, save, scene_name, title_time
from .rundir import read_summary

FIGURE = "fault_margins.png"
MODES = ("slip", "open", "break")
DEFAULT_THRESHOLDS = (1.0, 5.0, 10.0)


@dataclass
class MarginSnapshot:
    """The fault faces at one output time of fault.h5: mesh (serial points), fault index, margin (m), mode code,
    area (m^2), time (s)."""
    points: np.ndarray
    faces: np.ndarray
    fault: np.ndarray
    margin: np.ndarray
    mode: np.ndarray
    time: float


def read_margins(run_dir: str, step: int = -1) -> MarginSnapshot | None:
    """The margins at output time ``step`` of fault.h5; None when the run has none (no fault, margins off, or a
    source that loads no cell)."""
    path = os.path.join(run_dir, "fault.h5")
    if not os.path.exists(path):
        return None
    with open_h5(path, "r") as f:
        keys = sorted(f.get("steps", {}))
        if not keys:
            return None
        if not -len(keys) <= step < len(keys):
            raise IndexError(f"{path}: output time {step} out of range ({len(keys)} times written)")
        g = f["steps"][keys[step]]
        if "margin_drawdown_m" not in g:
            return None
        n = len(f["mesh/cells"])
        return MarginSnapshot(f["mesh/points"][...], f["mesh/cells"][...].astype(np.int64),
                              g["fault"][...].astype(np.int64) if "fault" in g else np.zeros(n, np.int64),
                              g["margin_drawdown_m"][...].astype(float), g["margin_mode"][...].astype(np.int64),
                              float(g.attrs["time"]))


def thresholds(run_dir: str) -> tuple:
    """The drawdowns (m) of the run's margin bands: the keys of a step record's ``area_within_m2``."""
    try:
        steps = read_summary(run_dir).get("steps", [])
    except (OSError, ValueError):
        steps = []
    for rec in steps:
        for fault in rec.get("faults", {}).values():
            within = fault.get("margin", {}).get("area_within_m2")
            if within:
                return tuple(sorted(float(k) for k in within))
    return DEFAULT_THRESHOLDS


def margin_figure(run_dir: str, out: str | None = None, step: int = -1) -> str | None:
    """``fault_margins.png`` at one output time (one panel per fault); returns its path, or None when the run
    has no margins."""
    snap = read_margins(run_dir, step)
    if snap is None:
        return None
    plt = pyplot()
    names = fault_names(run_dir)
    ids = [int(k) for k in np.unique(snap.fault)]
    fig, axs = plt.subplots(len(ids), 1, figsize=(11, 3.8 * len(ids) + 0.6), constrained_layout=True, squeeze=False)
    bands = thresholds(run_dir)
    for ax, k in zip(axs[:, 0], ids):
        _panel(fig, ax, snap, snap.fault == k, names[k] if k < len(names) else f"fault {k}", bands)
    fig.suptitle(f"{scene_name(run_dir)}: margins to failure, further drawdown of the loaded materials (m of head), "
                 f"{title_time(snap.time)}")
    return save(fig, out or os.path.join(run_dir, FIGURE))


def _bands(margin: np.ndarray, bands: tuple) -> np.ndarray:
    """Band of each margin: 0 failed now, 1 .. len(bands) within each threshold, len(bands) + 1 beyond the last,
    len(bands) + 2 never."""
    k = np.searchsorted(np.asarray(bands), margin, side="left") + 1
    k = np.where(margin <= 0.0, 0, k)
    return np.where(np.isfinite(margin), k, len(bands) + 2)


def plane_coordinates(points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, str, str]:
    """Coordinates of ``points`` in a fault's plane (mean unit normal of ``normals``): the distance along its strike
    (the horizontal direction in it, from its first point's) and z; a (near) horizontal fault in x, y."""
    n = normals.mean(axis=0)
    n /= max(np.linalg.norm(n), 1e-300)
    if abs(n[2]) > 0.99:
        return points[:, 0], points[:, 1], "x (m)", "y (m)"
    strike = np.cross([0.0, 0.0, 1.0], n)
    strike /= np.linalg.norm(strike)
    along = points @ strike
    azimuth = np.degrees(np.arctan2(strike[0], strike[1])) % 360.0
    return along, points[:, 2], f"along strike (m, azimuth {azimuth:.0f} degrees)", "z (m, stretched)"


def _panel(fig: Any, ax: Any, snap: MarginSnapshot, mine: np.ndarray, name: str, bands: tuple) -> None:
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.tri import Triangulation
    faces = snap.faces[mine]
    margin, mode = snap.margin[mine], snap.mode[mine]
    normals, area, centroids = face_geometry(snap.points, faces)
    u, v, xlabel, ylabel = plane_coordinates(snap.points, normals)
    tri = Triangulation(u, v, faces)
    nb = len(bands)
    colours = ["0.3"] + _colours(nb + 1) + ["0.88"]
    labels = ["failed now"] + [f"<= {b:g} m" for b in bands] + [f"> {bands[-1]:g} m", "never"]
    band = _bands(margin, bands)
    pc = ax.tripcolor(tri, facecolors=band.astype(float), cmap=ListedColormap(colours),
                      norm=BoundaryNorm(np.arange(nb + 4) - 0.5, nb + 3), edgecolors="none")
    cb = fig.colorbar(pc, ax=ax, pad=0.01, ticks=np.arange(nb + 3))
    cb.ax.set_yticklabels(labels, fontsize=8)
    cb.set_label("margin (m of further drawdown)")
    live = np.isfinite(margin) & (margin > 0)
    areas = ", ".join(f"{b:g} m: {area[margin <= b].sum():,.0f}" for b in bands)
    failed = band == 0
    n = int(np.count_nonzero(failed))
    text = f"failed now {n} face{'s' * (n != 1)}, {area[failed].sum():,.0f} m^2; area within {areas} m^2"
    if live.any():
        j = np.flatnonzero(live)[np.argmin(margin[live])]
        c = faces[j]
        ax.plot(u[c].mean(), v[c].mean(), marker="*", ms=15, mfc="white", mec="black", ls="none")
        mname = MODES[mode[j]] if 0 <= mode[j] < len(MODES) else "?"
        where = ", ".join(f"{x:.6g}" for x in centroids[j])
        title = f"{name}: smallest margin {margin[j]:.4g} m ({mname}, starred) at ({where}) m of the mesh"
    elif failed.all():
        title = f"{name}: every face has failed (slipping, open or broken)"
    else:
        title = f"{name}: no stuck face fails under further drawdown"
    ax.set_title(f"{title}\n{text}", fontsize=9.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_xlim(u[faces].min(), u[faces].max())
    ax.set_ylim(v[faces].min(), v[faces].max())


def _colours(n: int) -> list:
    """n colours from red (the smallest margins) to green."""
    from matplotlib import colormaps
    cmap = colormaps["RdYlGn"]
    return [cmap(0.08 + 0.84 * i / max(n - 1, 1)) for i in range(n)]
