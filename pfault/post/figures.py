"""PNG figures of a run directory (matplotlib, Agg backend), on rank 0 from the files pfault.io.output wrote.

A run writes them at its end (``-pfault_figures``, default true; pfault.simulation), and

    python -m pfault.post.figures RUN_DIR [RUN_DIR ...] [--step K]

writes them into any RUN_DIR (an interrupted run's too):

- ``fault_opening_slip.png`` (faults only): the opening of the open faces and the slip magnitude of the faces
  that have slid (zero elsewhere; the titles count the faces stuck, slipping and open) over the fault plane,
  one colour per fault triangle, in fault-plane coordinates ((y, z) for a vertical fault x = const; the vertical axis is
  stretched), and along-strike profiles of the largest opening and slip and of the mean dip slip (like
  Figs 3 and 6 of Franceschini et al., Proc. IAHS 372, 2015);
- ``subsidence_map.png``: land subsidence -u_z on the top surface (filled contours on the surface
  triangles of the mesh, so the jump across a fault trace is kept), with the fault trace and the wells;
  for groundwater-flow scenes a second panel maps the drawdown in the node layer where it is largest
  (like Figs 4 and 7);
- ``histories.png``: maximum subsidence, opening, slip (and drawdown) against time from summary.json, with
  the Newton iterations and factorisations per step;
- ``hazard_map.png``: the earth-fissure hazard fields of the land surface (pfault.hazard): largest
  horizontal principal strain and angular distortion, with the fault traces and the maxima marked, and the traces
  of the fissures that formed and reached the land surface (pfault.post.fissures);
- ``fissure_break.png`` (faults with a tensile strength that broke, pfault.post.fissures): each fault's broken
  faces coloured by the year they broke, intact faces grey, with the fissure's depth, length and first break;
- ``fault_margins.png`` (faults with margins to failure, pfault.post.margin_map): each fault's faces banded by their
  margin (m of further drawdown: failed now, within each of the run's thresholds, beyond, never), the smallest
  starred;
- ``insar_los.png`` (``-pfault_insar_los``): the LOS raster's displacement and velocity at its last time
  (pfault.io.insar).

Each PNG is written whole into ``NAME.png.tmp`` and renamed over the old one.

``K`` is the index of the output time (default -1: the last one). The figures read the run directory through
pfault.post.rundir and measure its meshes with pfault.post.meshes (whose sign conventions they follow).
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

import numpy as np

from ..hazard import same_place
from ..io.insar import NC_NAME, read_netcdf
from ..units import YEAR, format_time
from .fissures import draw_surface_traces, fissure_figure
from .margin_map import margin_figure
from .meshes import dip_slip, face_geometry, plane_axes, top_surface
from .plots import pyplot, save, scene_name, title_time
from .rundir import SUMMARY, has_fault, has_surface, read_fault, read_fields, read_options, read_summary, read_surface

FIGURES = ("fault_opening_slip.png", "subsidence_map.png", "histories.png", "hazard_map.png")
INSAR_FIGURE = "insar_los.png"


def _summary(run_dir: str) -> dict[str, Any]:
    """summary.json of the run whose figures are drawn (FileNotFoundError when it has none)."""
    summary = read_summary(run_dir)
    if summary is None:
        raise FileNotFoundError(os.path.join(run_dir, SUMMARY))
    return summary


def wells_from_options(options: dict[str, str]) -> np.ndarray:
    """Well (x, y) pairs of a flow scene from its resolved options, or an empty (0, 2) array."""
    raw = options.get("pfault_flow_wells", "")
    try:
        vals = [float(v) for v in raw.split(",") if v.strip()]
    except ValueError:
        vals = []
    return np.array(vals[: len(vals) // 2 * 2]).reshape(-1, 2)


# ------------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------------
def _binned(s, values, nbins, how):
    """Per-bin reduction ('max' or 'mean') of values over the along-strike coordinate s; NaN in empty bins."""
    edges = np.linspace(s.min(), s.max(), nbins + 1)
    b = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, nbins - 1)
    count = np.bincount(b, minlength=nbins)
    if how == "mean":
        out = np.bincount(b, weights=values, minlength=nbins) / np.maximum(count, 1)
    else:
        out = np.full(nbins, -np.inf)
        np.maximum.at(out, b, values)
    out[count == 0] = np.nan
    return 0.5 * (edges[1:] + edges[:-1]), out


def fault_figure(run_dir: str, out: str | None = None, step: int = -1) -> str:
    """Opening and slip over the fault plane(s) at one output time; returns the PNG path."""
    plt = pyplot()
    from matplotlib.tri import Triangulation
    snap = read_fault(run_dir, step)
    pts, tris, cd = snap.points, snap.cells, snap.cell_data
    normals, _, centroids = face_geometry(pts, tris)
    axis, (ia, ib) = plane_axes(normals)
    names = "xyz"
    # the opening of open faces and the slip of faces that have slid; a closed face's jump is the discretisation's
    state = cd["state"]
    slid = cd["slid"] != 0 if "slid" in cd else state != 0     # (a run written before the flag)
    opening_cm = 100.0 * np.where(state == 2, cd["opening"], 0.0)
    slip_cm = 100.0 * np.where(slid, cd["slip_magnitude"], 0.0)
    dip_cm = 100.0 * np.where(slid, dip_slip(cd["slip"], normals), 0.0)
    counts = np.bincount(state, minlength=3)
    faces = f"{counts[0]} stuck, {counts[1]} slipping, {counts[2]} open"
    tri = Triangulation(pts[:, ia], pts[:, ib], tris)
    scene = scene_name(run_dir)
    plane = float(np.median(centroids[:, axis]))

    fig, axs = plt.subplots(3, 1, figsize=(11, 9.5), constrained_layout=True,
                            gridspec_kw={"height_ratios": [1, 1, 1.1]})
    panels = ((opening_cm, "viridis", "opening (cm)", "opening of the open faces"),
              (slip_cm, "magma", "slip (cm)", "slip of the faces that have slid"))
    for ax, (val, cmap, label, what) in zip(axs[:2], panels):
        vmax = max(float(np.max(val, initial=0.0)), 1e-6)
        pc = ax.tripcolor(tri, facecolors=val, cmap=cmap, vmin=0.0, vmax=vmax, edgecolors="none")
        cb = fig.colorbar(pc, ax=ax, pad=0.01)
        cb.set_label(label)
        ax.set_title(f"{scene}: {what}, max {vmax:.3g} cm ({faces}), {title_time(snap.time)}")
        ax.set_xlabel(f"{names[ia]} (m), along the fault plane {names[axis]} = {plane:g} m")
        ax.set_ylabel(f"{names[ib]} (m, stretched)")
        ax.set_xlim(pts[tris, ia].min(), pts[tris, ia].max())
        ax.set_ylim(pts[tris, ib].min(), pts[tris, ib].max())
    # along-strike profiles: largest opening and slip over the depth, mean dip slip
    s = centroids[:, ia]
    nbins = int(np.clip(len(tris) // 8, 20, 300))
    ax = axs[2]
    for val, how, style, label in ((opening_cm, "max", "-", "max opening over depth"),
                                   (slip_cm, "max", "-", "max slip magnitude over depth"),
                                   (dip_cm, "mean", "--", "mean dip slip (+: plus side up)")):
        c, v = _binned(s, val, nbins, how)
        ax.plot(c, v, style, label=label)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlim(s.min(), s.max())
    ax.set_xlabel(f"{names[ia]} along the fault (m)")
    ax.set_ylabel("cm")
    side = f"plus side: {names[axis]} > {plane:g} m" if axis < 2 else "plus side: above"
    ax.set_title(f"profiles along strike ({side}; dip slip = u_z(plus) - u_z(minus) on a vertical fault)")
    ax.legend(loc="best", fontsize=9)
    ax.grid(alpha=0.3)
    out = out or os.path.join(run_dir, FIGURES[0])
    return save(fig, out)


def _fault_trace(run_dir, ztop, rtol=1e-9):
    """The fault traces on the land surface: the edges of fault triangles lying on it, as points (k, 2) of
    segments separated by NaN rows (one line for a plot however many faults meet), or None."""
    if not has_fault(run_dir):
        return None
    snap = read_fault(run_dir, 0)
    pts = snap.points
    on = np.abs(pts[:, 2] - ztop) <= rtol * max(np.ptp(pts, axis=0).max(), 1.0)
    edges = np.concatenate([snap.cells[:, [0, 1]], snap.cells[:, [1, 2]], snap.cells[:, [2, 0]]])
    edges = np.unique(np.sort(edges[on[edges].all(axis=1)], axis=1), axis=0)
    if not len(edges):
        return None
    seg = np.concatenate([pts[edges][:, :, :2], np.full((len(edges), 1, 2), np.nan)], axis=1)
    return seg.reshape(-1, 2)


def _trace_x(trace, y0=None):
    """x of the fault traces for a profile along x: where they cross y = y0, or (y0 None) those of the trace
    segments running along y."""
    seg = trace.reshape(-1, 3, 2)[:, :2]
    (x0, ya), (x1, yb) = seg[:, 0].T, seg[:, 1].T
    if y0 is None:
        along = np.abs(yb - ya) > np.abs(x1 - x0)
        return np.unique(np.round(np.r_[x0[along], x1[along]], 3))
    lo, hi = np.minimum(ya, yb), np.maximum(ya, yb)
    cross = (lo <= y0) & (y0 <= hi) & (hi > lo)
    t = (y0 - ya[cross]) / (yb[cross] - ya[cross])
    return np.unique(np.round(x0[cross] + t * (x1[cross] - x0[cross]), 3))


def _layer_with_largest(points, values, rtol=1e-9):
    """z of the horizontal node layer holding the largest value, and the mask of its nodes."""
    z = points[:, 2]
    tol = rtol * max(np.ptp(points, axis=0).max(), 1.0)
    zl = z[int(np.argmax(values))]
    return zl, np.abs(z - zl) <= tol


def profile_along_x(points: np.ndarray, tris: np.ndarray, values: np.ndarray, xs: np.ndarray,
                    y0: float) -> np.ndarray:
    """P1 values on surface triangles sampled at (xs, y0) (NaN outside). Split fault vertices make the
    triangulation non-conforming for matplotlib's tri finders, so this is a direct barycentric search over
    the triangles whose y-range holds y0; at a point on a fault trace the first triangle found wins."""
    P = points[tris][:, :, :2]
    band = (P[:, :, 1].min(axis=1) <= y0) & (P[:, :, 1].max(axis=1) >= y0)
    P, T = P[band], tris[band]
    x0 = P[:, 0]
    e1, e2 = P[:, 1] - x0, P[:, 2] - x0
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    qx = xs[None, :] - x0[:, :1]
    qy = (y0 - x0[:, 1])[:, None]
    l1 = (qx * e2[:, 1:2] - qy * e2[:, 0:1]) / det[:, None]
    l2 = (e1[:, 0:1] * qy - e1[:, 1:2] * qx) / det[:, None]
    l0 = 1.0 - l1 - l2
    eps = 1e-9
    inside = (l0 >= -eps) & (l1 >= -eps) & (l2 >= -eps)
    j = np.argmax(inside, axis=0)
    cols = np.arange(len(xs))
    v = values[T]
    out = l0[j, cols] * v[j, 0] + l1[j, cols] * v[j, 1] + l2[j, cols] * v[j, 2]
    return np.where(inside.any(axis=0), out, np.nan)


def _nice_levels(vmin, vmax, n=20):
    from matplotlib.ticker import MaxNLocator
    if not vmax > vmin:
        vmax = vmin + 1e-6
    return MaxNLocator(nbins=n).tick_values(vmin, vmax)


def _map_layout(plt, pts, ncol):
    """The figure: ``ncol`` maps, and the profile beside them (a domain long in y) or below; returns the figure,
    its grid and the profile's place."""
    lx, ly = np.ptp(pts[:, 0]), np.ptp(pts[:, 1])
    map_h = min(max(5.2 * ly / lx, 4.2), 8.5)
    tall = ly > 1.5 * lx            # profile beside the map(s) rather than below
    if tall:
        fig = plt.figure(figsize=(map_h * lx / ly * 1.6 * ncol + 6.0, map_h), constrained_layout=True)
        gs = fig.add_gridspec(1, ncol + 1, width_ratios=[1.0] * ncol + [1.6])
        prof_spec = gs[0, ncol].subgridspec(3, 1, height_ratios=[1, 2, 1])[1]
    else:
        fig = plt.figure(figsize=(6.4 * ncol, map_h + 3.2), constrained_layout=True)
        gs = fig.add_gridspec(2, ncol, height_ratios=[map_h, 2.6])
        prof_spec = gs[1, :]
    return fig, gs, prof_spec


def _decorate_map(ax, trace, wells, km):
    """The fault trace and the wells on a map, its aspect, axes and legend."""
    if trace is not None:
        ax.plot(trace[:, 0] * km, trace[:, 1] * km, "w-", lw=2.2)
        ax.plot(trace[:, 0] * km, trace[:, 1] * km, "k--", lw=1.0, label="fault trace")
    if len(wells):
        ax.plot(wells[:, 0] * km, wells[:, 1] * km, "v", ms=7, mfc="white", mec="black", label="wells")
    ax.set_aspect("equal")
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    if trace is not None or len(wells):
        ax.legend(loc="upper right", fontsize=8, framealpha=0.8)


def _contour_map(fig, ax, tri, values, cmap, label):
    """Filled contours of ``values`` on ``tri`` from min(0, smallest) to the largest, with its colour bar."""
    levels = _nice_levels(min(0.0, float(np.min(values))), float(np.max(values)))
    cf = ax.tricontourf(tri, values, levels=levels, cmap=cmap)
    ax.tricontour(tri, values, levels=levels[::2], colors="k", linewidths=0.4, alpha=0.5)
    cb = fig.colorbar(cf, cax=ax.inset_axes([1.03, 0.0, 0.04, 1.0]))
    cb.set_label(label)


def _drawdown_map(fig, ax, pts, head, km):
    """The drawdown on the horizontal node layer where it is largest; returns that layer's z and the largest
    drawdown (m)."""
    from matplotlib.tri import Triangulation
    dd = -head
    zl, layer = _layer_with_largest(pts, dd)
    xy, idx = np.unique(np.round(pts[layer, :2], 6), axis=0, return_index=True)
    d = dd[np.flatnonzero(layer)[idx]]
    _contour_map(fig, ax, Triangulation(xy[:, 0] * km, xy[:, 1] * km), d, "Blues", "drawdown (m of head)")
    return zl, float(d.max())


def _profile(ax, pts, top, sub, y0, trace, wells, km):
    """Subsidence along x at y0 (both sides of a fault trace are kept apart by the surface triangles; the
    interpolation picks one side exactly on the trace), the fault trace dashed and the wells dotted."""
    x = np.linspace(pts[:, 0].min(), pts[:, 0].max(), 1201)
    prof = profile_along_x(pts, top, sub, x, y0)
    ax.plot(x * km, prof, color="tab:red")
    if trace is not None:
        for xt in _trace_x(trace, y0):
            ax.axvline(xt * km, color="k", ls="--", lw=0.8)
    if len(wells):
        for wx in wells[:, 0]:
            ax.axvline(wx * km, color="tab:blue", ls=":", lw=0.8)
    ax.invert_yaxis()
    ax.set_xlim(x[0] * km, x[-1] * km)
    ax.set_xlabel("x (km)")
    ax.set_ylabel("subsidence (m), down")
    ax.set_title(f"subsidence profile along y = {y0 * km:.3g} km (dashed: fault trace" +
                 (", dotted: wells)" if len(wells) else ")"), fontsize=10)
    ax.grid(alpha=0.3)


def subsidence_figure(run_dir: str, out: str | None = None, step: int = -1) -> str:
    """Land subsidence map (and the drawdown map of flow scenes) at one output time, with a subsidence profile
    along x through the point of largest subsidence; returns the PNG path."""
    plt = pyplot()
    from matplotlib.tri import Triangulation
    snap = read_fields(run_dir, step)
    pts, tets = snap.points, snap.cells
    sub = -snap.point_data["displacement"][:, 2]
    top = top_surface(pts, tets)
    on_top = np.unique(top)
    wells = wells_from_options(read_options(run_dir))
    trace = _fault_trace(run_dir, pts[:, 2].max())
    head = snap.point_data.get("head_change")
    km = 1e-3
    fig, gs, prof_spec = _map_layout(plt, pts, 2 if head is not None else 1)

    ax = fig.add_subplot(gs[0, 0])
    imax = on_top[int(np.argmax(sub[on_top]))]
    smax = float(sub[imax])
    levels = _nice_levels(min(0.0, float(np.min(sub[on_top]))), smax)
    tri = Triangulation(pts[:, 0] * km, pts[:, 1] * km, top)
    cf = ax.tricontourf(tri, sub, levels=levels, cmap="YlOrRd")
    ax.tricontour(tri, sub, levels=levels[::2], colors="k", linewidths=0.4, alpha=0.5)
    cb = fig.colorbar(cf, cax=ax.inset_axes([1.03, 0.0, 0.04, 1.0]))
    cb.set_label("subsidence -u_z (m)")
    y0 = float(pts[imax, 1])
    ax.axhline(y0 * km, color="tab:blue", lw=0.8, ls=":", label="profile")
    ax.set_title(f"{scene_name(run_dir)}: land subsidence, max {smax:.3g} m\n{title_time(snap.time)}")
    _decorate_map(ax, trace, wells, km)

    if head is not None:
        ax = fig.add_subplot(gs[0, 1])
        zl, dmax = _drawdown_map(fig, ax, pts, head, km)
        ax.set_title(f"drawdown at z = {zl:g} m (the node layer where it is largest), max {dmax:.3g} m\n"
                     f"{title_time(snap.time)}", fontsize=10)
        _decorate_map(ax, trace, wells, km)

    _profile(fig.add_subplot(prof_spec), pts, top, sub, y0, trace, wells, km)
    out = out or os.path.join(run_dir, FIGURES[1])
    return save(fig, out)


def histories_figure(run_dir: str, out: str | None = None) -> str:
    """Maxima against time and solver work per step, from summary.json; returns the PNG path."""
    plt = pyplot()
    summary = _summary(run_dir)
    steps = summary["steps"]
    t = np.array([r["time_s"] for r in steps]) / YEAR

    def col(key):
        return np.array([r.get(key, 0.0) for r in steps], dtype=float)

    panels = [("max_subsidence_m", "max land subsidence", "m", 1.0)]
    if any("max_fault_opening_m" in r for r in steps):
        panels += [("max_fault_opening_m", "max fault opening (open faces)", "cm", 100.0),
                   ("max_fault_slip_m", "max fault slip (faces that have slid)", "cm", 100.0)]
    if any("max_drawdown_m" in r for r in steps):
        panels.append(("max_drawdown_m", "max drawdown", "m of head", 1.0))
    n = len(panels) + 1
    ncol = 3 if n > 4 else 2
    nrow = -(-n // ncol)
    fig, axs = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.4 * nrow), constrained_layout=True, squeeze=False)
    axs = axs.ravel()
    for ax, (key, title, unit, scale) in zip(axs, panels):
        ax.plot(t, scale * col(key), "o-", ms=4)
        ax.set_title(title)
        ax.set_xlabel("time (years)")
        ax.set_ylabel(unit)
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
    ax = axs[len(panels)]
    newton = col("newton_its")
    fact = col("factorizations")
    width = 0.8 * (t[1] - t[0]) if len(t) > 1 else 0.8
    ax.bar(t, newton, width=width, color="tab:blue", label="Newton iterations")
    if np.any(fact > 0):
        ax.plot(t, fact, "s", color="tab:red", label="factorisations")
    ax.set_title("solver work per step")
    ax.set_xlabel("time (years)")
    ax.set_ylabel("count")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    for ax in axs[len(panels) + 1:]:
        ax.set_visible(False)
    fig.suptitle(f"{summary.get('scene', '')}: {summary['mesh']['nodes']:,} nodes, {summary['mesh']['cells']:,} "
                 f"tetrahedra, {summary['ranks']} rank(s)" + ("" if summary.get("converged", True)
                                                              else " (a step did NOT converge)"))
    out = out or os.path.join(run_dir, FIGURES[2])
    return save(fig, out)


def hazard_figure(run_dir: str, out: str | None = None, step: int = -1) -> str:
    """Earth-fissure hazard map of the land surface at one output time: largest horizontal principal strain
    (the fissure-prone zone outlined) and angular distortion per surface triangle, fault traces dashed, maxima
    marked, and the largest value of each over y against x; returns the PNG path."""
    plt = pyplot()
    from matplotlib.tri import Triangulation

    snap = read_surface(run_dir, step)
    pts, tris, cd = snap.points, snap.cells, snap.cell_data
    trace = _fault_trace(run_dir, pts[:, 2].max())
    km = 1e-3
    lx, ly = np.ptp(pts[:, 0]), np.ptp(pts[:, 1])
    map_h = min(max(5.0 * ly / max(lx, 1e-300), 4.0), 8.0)
    fig = plt.figure(figsize=(max(2 * map_h * lx / max(ly, 1e-300) * 1.35 + 1.5, 9.0), map_h + 3.6),
                     constrained_layout=True)
    gs = fig.add_gridspec(2, 2, height_ratios=[map_h, 2.6])
    tri = Triangulation(pts[:, 0] * km, pts[:, 1] * km, tris)
    centroids = pts[tris].mean(axis=1)
    panels = (("horizontal_strain", "RdBu_r", "largest horizontal principal strain (tension +)"),
              ("angular_distortion", "viridis", "angular distortion |grad u_z|"))
    for col, (key, cmap, label) in enumerate(panels):
        ax = fig.add_subplot(gs[0, col])
        val = cd[key]
        i = int(np.argmax(val))
        vmax = max(float(np.max(np.abs(val))), 1e-12)
        vmin = -vmax if key == "horizontal_strain" else 0.0
        pc = ax.tripcolor(tri, facecolors=val, cmap=cmap, vmin=vmin, vmax=vmax, edgecolors="none")
        fig.colorbar(pc, ax=ax, shrink=0.9, pad=0.02).set_label(label)
        if trace is not None:
            ax.plot(trace[:, 0] * km, trace[:, 1] * km, "k--", lw=1.0, label="fault trace")
        ax.plot(centroids[i, 0] * km, centroids[i, 1] * km, "*", ms=13, mfc="gold", mec="black",
                label=f"max {val[i]:.3g} at ({centroids[i, 0]:.0f}, {centroids[i, 1]:.0f}) m")
        if key == "horizontal_strain":
            _fissure_prone_outline(ax, run_dir, pts, tris, val, snap.time, km)
        draw_surface_traces(ax, run_dir, snap.time, km)
        ax.set_aspect("equal")
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
        ax.set_title(f"{label.split(' (')[0]}, {title_time(snap.time)}", fontsize=10)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8, ncol=1, framealpha=0.85)
    # across the maps: the largest value over y in bins of x
    ax = fig.add_subplot(gs[1, :])
    nbins = int(np.clip(len(tris) // 20, 20, 400))
    for key, color in (("horizontal_strain", "tab:red"), ("angular_distortion", "tab:green")):
        c, v = _binned(centroids[:, 0], cd[key], nbins, "max")
        ax.plot(c * km, v, color=color, label=f"largest {key.replace('_', ' ')} over y")
    if trace is not None:
        for xt in _trace_x(trace):
            ax.axvline(xt * km, color="k", ls="--", lw=0.8)
    ax.set_xlim(pts[:, 0].min() * km, pts[:, 0].max() * km)
    ax.set_xlabel("x (km)")
    ax.set_ylabel("strain, slope (-)")
    ax.set_title("profile across the maps (dashed: fault trace)", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.suptitle(f"{scene_name(run_dir)}: earth-fissure hazard of the land surface")
    out = out or os.path.join(run_dir, FIGURES[3])
    return save(fig, out)


def _fissure_prone_outline(ax: Any, run_dir: str, pts: np.ndarray, tris: np.ndarray, strain: np.ndarray, t: float,
                           km: float) -> None:
    """The border of the triangles whose strain exceeds summary.json's hazard_strain_threshold, labelled with
    the fissure-prone length of the step at time t (pfault.hazard); nothing for a run without them. A fault's
    trace inside the zone is no border: its two sides' copies of a vertex are one point (hazard.same_place)."""
    from matplotlib.collections import LineCollection
    summary = _summary(run_dir)
    threshold = summary.get("hazard_strain_threshold")
    if threshold is None or not np.any(strain > threshold):
        return
    edges = np.sort(same_place(pts)[tris[strain > threshold]][:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges, count = np.unique(edges, axis=0, return_counts=True)
    border = pts[edges[count == 1]][:, :, :2] * km
    rec = [r for r in summary.get("steps", []) if abs(r.get("time_s", -1.0) - t) <= 1e-9 * max(abs(t), 1.0)]
    length = rec[-1].get("fissure_prone_length_m") if rec else None
    text = f", {length / 1e3:.3g} km long" if length is not None else ""
    ax.add_collection(LineCollection(border, colors="black", linewidths=0.8,
                                     label=f"fissure-prone (strain > {threshold:g}){text}"))


def insar_figure(run_dir: str) -> str | None:
    """``insar_los.png``: the last output time's LOS displacement (mm) and velocity (mm/yr); None without a
    raster."""
    path = os.path.join(run_dir, NC_NAME)
    if not os.path.exists(path):
        return None
    plt = pyplot()
    d = read_netcdf(path)
    dx = d["x"][1] - d["x"][0] if len(d["x"]) > 1 else 1.0
    dy = d["y"][1] - d["y"][0] if len(d["y"]) > 1 else 1.0
    extent = (d["x"][0] - dx / 2, d["x"][-1] + dx / 2, d["y"][0] - dy / 2, d["y"][-1] + dy / 2)
    panel = float(np.clip(4.5 * (extent[1] - extent[0]) / (extent[3] - extent[2]), 2.5, 8.0))    # map's aspect
    fig, axes = plt.subplots(1, 2, figsize=(2 * panel + 3.0, 4.8), constrained_layout=True)
    panels = ((d["los_displacement"][-1] * 1e3, "LOS displacement (mm)"),
              (d["los_velocity"][-1] * 1e3 * YEAR, "LOS velocity (mm/yr, since the previous output)"))
    for ax, (values, label) in zip(axes, panels):
        lim = float(np.nanmax(np.abs(values))) if np.isfinite(values).any() else 1.0
        im = ax.imshow(values, origin="lower", extent=extent, cmap="RdBu_r", vmin=-lim or -1, vmax=lim or 1)
        fig.colorbar(im, ax=ax, label=label)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
    e, n, u = d["los"] if d["los"].ndim == 1 else d["los"].mean(axis=0)
    which = "LOS" if d["los"].ndim == 1 else "mean LOS of the product's pixels"
    fig.suptitle(f"t = {format_time(d['time'][-1]).strip()}; {which} (e, n, u) = ({e:.3f}, {n:.3f}, {u:.3f}), "
                 "positive towards the satellite")
    out = os.path.join(run_dir, INSAR_FIGURE)
    fig.savefig(out + ".tmp", dpi=120, format="png")
    plt.close(fig)
    os.replace(out + ".tmp", out)
    return out


def make_figures(run_dir: str, step: int = -1) -> list[str]:
    """All figures of a run directory; returns the paths written."""
    paths = []
    if has_fault(run_dir):
        paths.append(fault_figure(run_dir, step=step))
        broken = fissure_figure(run_dir, step=step)     # faults with a tensile strength that broke
        if broken is not None:
            paths.append(broken)
        margins = margin_figure(run_dir, step=step)     # the faces' margins to failure (-pfault_margins)
        if margins is not None:
            paths.append(margins)
    paths.append(subsidence_figure(run_dir, step=step))
    paths.append(histories_figure(run_dir))
    if has_surface(run_dir):
        paths.append(hazard_figure(run_dir, step=step))
    insar = insar_figure(run_dir)       # the LOS raster's last time (-pfault_insar_los)
    if insar is not None:
        paths.append(insar)
    return paths


def write_run_figures(run_dir: str) -> list[str]:
    """The figures a finished run writes next to its output (rank 0). A figure that fails is reported, not
    raised: the run's results are on disk already."""
    try:
        return make_figures(run_dir)
    except Exception as exc:          # noqa: BLE001 (plotting must not turn a finished run into a failure)
        sys.stderr.write(f"pfault: warning: figures not written ({type(exc).__name__}: {exc}); "
                         f"python -m pfault.post.figures {run_dir} makes them\n")
        return []


def main(argv: list[str] | None = None) -> int:
    """``python -m pfault.post.figures RUN_DIR [RUN_DIR ...] [--step K]``: the figures of each run directory; exit
    code 1 when one is not a pfault run directory."""
    ap = argparse.ArgumentParser(prog="python -m pfault.post.figures", description=__doc__.splitlines()[0],
                                 epilog=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="a pfault output directory")
    ap.add_argument("--step", type=int, default=-1, help="output time index (default -1: the last)")
    args = ap.parse_args(argv)
    status = 0
    for d in args.run_dirs:
        if not os.path.exists(os.path.join(d, "summary.json")):
            sys.stderr.write(f"figures: {d}: no summary.json (not a pfault run directory)\n")
            status = 1
            continue
        for p in make_figures(d, args.step):
            print(p)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
