"""Earth-fissure hazard fields of the land surface, from the displacement relative to the initial state.

Per surface triangle (P1 displacement: constant gradient), in the horizontal projection:

- ``horizontal_strain``: the largest principal value of the in-plane strain
  eps = sym(grad_xy (u_x, u_y)), tension positive; fissures open where it is largest;
- ``angular_distortion``: |grad_xy u_z|, the slope of the differential subsidence (what a building or
  a pipe crossing the surface must follow).

Triangles next to a split fault vertex use its copy on their own side, so a fault's opening or offset is a
discontinuity between triangles, not a strain. Nearly vertical triangles (projected area below 1e-9 of the
largest) carry zero. Rank 0, on the output mesh (pfault.simulation), NumPy only.

The fissure-prone length (``fissure_prone``) sums, over the connected zones of triangles whose horizontal strain
exceeds ``-pfault_hazard_strain_threshold``, the length of each zone along the direction a tension fissure would
run there (normal to the largest principal strain, averaged over the zone): the length of the land-surface trace a
fissure could take, which a plan's pumping lengthens or shortens. A zone is the triangles that touch one another
(share a point) on the land surface as it lies, so the two sides of a split fault, whose vertices the output mesh
holds twice (one copy per side, at the same place), join along its trace: a stretch of land surface strained on both
sides of a fault is one zone, counted once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .mesh.serial import TET_FACES, locate_faces

if TYPE_CHECKING:
    from .mesh.fault import FaultSplit
    from .mesh.serial import SerialMesh

FIELDS = ("horizontal_strain", "angular_distortion")


@dataclass
class Surface:
    vertices: np.ndarray     # (k,) output point ids
    points: np.ndarray       # (k, 3) their coordinates
    triangles: np.ndarray    # (m, 3) indices into points
    strain_threshold: float = 2e-4   # horizontal strain above which a triangle is fissure-prone


def land_surface(points: np.ndarray, tets: np.ndarray, serial: SerialMesh, split: FaultSplit | None,
                 name: str, strain_threshold: float = 2e-4) -> Surface | None:
    """The land surface on the output mesh (points, tets: split fault vertices appear once per piece, each cell
    uses its pieces' copies): the triangles of the physical surface ``name``, or those on the plane z = max z when the
    mesh has no such surface; None when neither gives a triangle."""
    tri = serial.surfaces.get(name)
    if tri is not None and len(tri):
        t, cell, lface = locate_faces(serial.tets, len(serial.points), tri)
        _, first = np.unique(t, return_index=True)
        faces = tets[cell[first][:, None], TET_FACES[lface[first]]]
    else:
        z = points[:, 2]
        on = np.abs(z - z.max()) <= 1e-9 * max(np.ptp(points, axis=0).max(), 1.0)
        faces = tets[:, TET_FACES].reshape(-1, 3)
        faces = faces[on[faces].all(axis=1)]
    if not len(faces):
        return None
    verts, inv = np.unique(faces, return_inverse=True)
    return Surface(vertices=verts, points=points[verts], triangles=inv.reshape(-1, 3).astype(np.int64),
                   strain_threshold=float(strain_threshold))


def _strain(points: np.ndarray, triangles: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per triangle: (ok, exx, eyy, exy, d u_z/dx, d u_z/dy) of the P1 displacement u (k, 3)."""
    x = points[triangles]
    e1, e2 = x[:, 1, :2] - x[:, 0, :2], x[:, 2, :2] - x[:, 0, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-9 * np.max(np.abs(det), initial=0.0)
    d = np.where(ok, det, 1.0)[:, None]
    du1, du2 = u[triangles[:, 1]] - u[triangles[:, 0]], u[triangles[:, 2]] - u[triangles[:, 0]]
    ddx = (e2[:, 1:2] * du1 - e1[:, 1:2] * du2) / d          # (m, 3): d u / dx
    ddy = (e1[:, 0:1] * du2 - e2[:, 0:1] * du1) / d          # d u / dy
    return ok, ddx[:, 0], ddy[:, 1], 0.5 * (ddy[:, 0] + ddx[:, 1]), ddx[:, 2], ddy[:, 2]


def surface_fields(points: np.ndarray, triangles: np.ndarray, u: np.ndarray) -> dict[str, np.ndarray]:
    """Hazard fields per triangle (dict of (m,) arrays) from the displacement u (k, 3) at the points."""
    ok, exx, eyy, exy, dzx, dzy = _strain(points, triangles, u)
    strain = 0.5 * (exx + eyy) + np.sqrt(0.25 * (exx - eyy) ** 2 + exy ** 2)
    distortion = np.hypot(dzx, dzy)
    return {"horizontal_strain": np.where(ok, strain, 0.0), "angular_distortion": np.where(ok, distortion, 0.0)}


def same_place(points: np.ndarray) -> np.ndarray:
    """For every point, the first point at the same place (itself if none before it): the copies of a split fault
    vertex, one per side in the output mesh (pfault.mesh.fault.vertex_copies), are one point of the land surface."""
    _, first, inv = np.unique(points, axis=0, return_index=True, return_inverse=True)
    return first[inv.ravel()]


def _zones(triangles: np.ndarray) -> np.ndarray:
    """Label (0..n-1) of the connected zone of every triangle: triangles sharing a point id are one zone (a
    triangle that touches a zone at a corner belongs to that stretch of land surface, and is not a fissure of its
    own)."""
    m = len(triangles)
    points, owner = triangles.ravel(), np.repeat(np.arange(m), 3)
    order = np.argsort(points, kind="stable")
    point, tri = points[order], owner[order]
    same = point[1:] == point[:-1]
    pairs = np.column_stack([tri[:-1][same], tri[1:][same]])     # triangles in turn around every shared point
    # each triangle's pairs in a row: the smallest label over them by one reduceat (np.minimum.at is ~10x slower)
    ends = pairs.T.ravel()
    order = np.argsort(ends, kind="stable")
    starts = np.flatnonzero(np.r_[True, ends[order][1:] != ends[order][:-1]]) if len(ends) else np.zeros(0, int)
    target = ends[order][starts]
    label = np.arange(m)
    while True:
        low = np.minimum(label[pairs[:, 0]], label[pairs[:, 1]])
        new = label.copy()
        if len(target):
            new[target] = np.minimum(new[target], np.minimum.reduceat(np.tile(low, 2)[order], starts))
        new = new[new]                                  # pointer jumping
        if np.array_equal(new, label):
            break
        label = new
    return np.unique(label, return_inverse=True)[1].ravel()


def fissure_prone(points: np.ndarray, triangles: np.ndarray, u: np.ndarray, threshold: float) -> dict[str, float]:
    """Fissure-prone length and area of the land surface (module docstring): the triangles whose horizontal
    strain exceeds ``threshold``, grouped in zones of triangles that touch at a point (``same_place``: across a
    split fault's trace too); per zone the union of the triangles' extents along the zone's mean fissure direction
    (area-weighted mean of the doubled angle), summed over the zones."""
    ok, exx, eyy, exy, _, _ = _strain(points, triangles, u)
    strain = 0.5 * (exx + eyy) + np.sqrt(0.25 * (exx - eyy) ** 2 + exy ** 2)
    prone = ok & (strain > threshold)
    out = {"fissure_prone_length_m": 0.0, "fissure_prone_area_m2": 0.0}
    if not prone.any():
        return out
    tri = triangles[prone]
    x = points[tri][:, :, :2]
    area = 0.5 * np.abs(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]))
    zone = _zones(same_place(points)[tri])
    two_theta = np.arctan2(2.0 * exy[prone], exx[prone] - eyy[prone])   # twice the tension direction's angle
    c = np.bincount(zone, area * np.cos(two_theta))
    s = np.bincount(zone, area * np.sin(two_theta))
    phi = 0.5 * np.arctan2(s, c)
    along = np.stack([-np.sin(phi), np.cos(phi)], axis=1)[zone]          # the fissure runs normal to the tension
    proj = np.einsum("tvk,tk->tv", x, along)
    lo, hi = proj.min(axis=1), proj.max(axis=1)
    base = np.full(zone.max() + 1, np.inf)
    np.minimum.at(base, zone, lo)
    lo, hi = lo - base[zone], hi - base[zone]
    shift = zone * 2.0 * (hi.max() + 1.0)                 # zones apart on one axis: one running maximum serves all
    order = np.lexsort((lo, zone))
    lo, hi = (lo + shift)[order], (hi + shift)[order]
    reach = np.concatenate([[-np.inf], np.maximum.accumulate(hi)[:-1]])
    out["fissure_prone_length_m"] = float(np.sum(np.maximum(hi - np.maximum(lo, reach), 0.0)))
    out["fissure_prone_area_m2"] = float(area.sum())
    return out


def maxima(points: np.ndarray, triangles: np.ndarray,
           fields: dict[str, np.ndarray]) -> dict[str, float | list[float] | None]:
    """{max_<field>: value, max_<field>_xy: [x, y] of the triangle's centroid} for both hazard fields."""
    out: dict[str, float | list[float] | None] = {}
    centroids = points[triangles].mean(axis=1)
    for name in FIELDS:
        values = fields[name]
        i = int(np.argmax(values)) if len(values) else None
        out[f"max_{name}"] = float(values[i]) if i is not None else 0.0
        out[f"max_{name}_xy"] = [float(c) for c in centroids[i, :2]] if i is not None else None
    return out


def summary_maxima(records: Sequence[dict[str, Any]], strain_threshold: float | None = None) -> dict[str, Any]:
    """The largest hazard values over the step records that have them, where and when they occur, and the
    strain threshold of the fissure-prone length."""
    out: dict[str, Any] = {} if strain_threshold is None else {"hazard_strain_threshold": float(strain_threshold)}
    for name in FIELDS:
        key = f"max_{name}"
        have = [r for r in records if r.get(key) is not None]
        if have:
            best = max(have, key=lambda r: r[key])
            out[key], out[key + "_xy"], out[key + "_time_s"] = best[key], best[key + "_xy"], best["time_s"]
    have = [r for r in records if r.get("fissure_prone_length_m") is not None]
    if have:
        best = max(have, key=lambda r: r["fissure_prone_length_m"])
        out["max_fissure_prone_length_m"] = best["fissure_prone_length_m"]
        out["max_fissure_prone_length_time_s"] = best["time_s"]
        out["final_fissure_prone_length_m"] = have[-1]["fissure_prone_length_m"]
    return out
