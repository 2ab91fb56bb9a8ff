"""Earth-fissure hazard fields of the land surface, from the displacement relative to the initial state.

Per surface triangle (P1 displacement: constant gradient), in the horizontal projection:

- ``horizontal_strain``: the largest principal value of the in-plane strain
  eps = sym(grad_xy (u_x, u_y)), tension positive; fissures open where it is largest;
- ``angular_distortion``: |grad_xy u_z|, the slope of the differential subsidence (what a building or
  a pipe crossing the surface must follow).

Triangles next to a split fault vertex use its copy on their own side, so a fault's opening or offset is a
discontinuity between triangles, not a strain. Nearly vertical triangles (projected area below 1e-9 of the
largest) carry zero. Rank 0, on the output mesh (pfault.simulation), NumPy only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..mesh.serial import TET_FACES, locate_faces

if TYPE_CHECKING:
    from ..mesh.fault import FaultSplit
    from ..mesh.serial import SerialMesh

FIELDS = ("horizontal_strain", "angular_distortion")


@dataclass
class Surface:
    vertices: np.ndarray     # (k,) output point ids
    points: np.ndarray       # (k, 3) their coordinates
    triangles: np.ndarray    # (m, 3) indices into points


def land_surface(points: np.ndarray, tets: np.ndarray, serial: SerialMesh, split: FaultSplit | None,
                 name: str) -> Surface | None:
    """The land surface on the output mesh (points, tets: split fault vertices appear twice, plus-side cells
    use the copies): the triangles of the physical surface ``name``, or those on the plane z = max z when the
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
    return Surface(vertices=verts, points=points[verts], triangles=inv.reshape(-1, 3).astype(np.int64))


def surface_fields(points: np.ndarray, triangles: np.ndarray, u: np.ndarray) -> dict[str, np.ndarray]:
    """Hazard fields per triangle (dict of (m,) arrays) from the displacement u (k, 3) at the points."""
    x = points[triangles]
    e1, e2 = x[:, 1, :2] - x[:, 0, :2], x[:, 2, :2] - x[:, 0, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-9 * np.max(np.abs(det), initial=0.0)
    d = np.where(ok, det, 1.0)[:, None]
    du1, du2 = u[triangles[:, 1]] - u[triangles[:, 0]], u[triangles[:, 2]] - u[triangles[:, 0]]
    ddx = (e2[:, 1:2] * du1 - e1[:, 1:2] * du2) / d          # (m, 3): d u / dx
    ddy = (e1[:, 0:1] * du2 - e2[:, 0:1] * du1) / d          # d u / dy
    exx, eyy, exy = ddx[:, 0], ddy[:, 1], 0.5 * (ddy[:, 0] + ddx[:, 1])
    strain = 0.5 * (exx + eyy) + np.sqrt(0.25 * (exx - eyy) ** 2 + exy ** 2)
    distortion = np.hypot(ddx[:, 2], ddy[:, 2])
    return {"horizontal_strain": np.where(ok, strain, 0.0), "angular_distortion": np.where(ok, distortion, 0.0)}


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


def summary_maxima(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The largest hazard values over the step records that have them, where and when they occur."""
    out: dict[str, Any] = {}
    for name in FIELDS:
        key = f"max_{name}"
        have = [r for r in records if r.get(key) is not None]
        if have:
            best = max(have, key=lambda r: r[key])
            out[key], out[key + "_xy"], out[key + "_time_s"] = best[key], best[key + "_xy"], best["time_s"]
    return out
