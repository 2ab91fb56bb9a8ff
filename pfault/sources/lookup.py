"""Where points of the FE mesh fall in a groundwater model's grid, as index and weight arrays (plain NumPy).

Every lookup returns ``(index, weight)``, each (npoints, k): the value at a point is ``sum(values[index] *
weight, axis=1)`` for a flat array ``values`` of the model's cells or nodes, and ``index`` is -1 on every column
of a point that is outside. The maps are computed once per run; reading a time's values is then a gather.

- A MODFLOW grid (DIS: rows and columns; DISV: polygons) gives the one cell that contains a point (k = 1), its
  layer from the top and bottom elevations: bottom < z <= top.
- A regular grid of nodes (axes x, y and optionally z) gives the multilinear interpolant (k = 4 or 8).
- Scattered points in the plane give the linear interpolant on their Delaunay triangulation (k = 3).
"""

from __future__ import annotations

import numpy as np


def to_model_xy(x: np.ndarray, y: np.ndarray, xorigin: float, yorigin: float,
                angrot: float) -> tuple[np.ndarray, np.ndarray]:
    """Site coordinates -> a MODFLOW model's own: the grid's corner at (xorigin, yorigin), its x axis rotated
    by ``angrot`` degrees counter-clockwise (MODFLOW 6's XORIGIN, YORIGIN, ANGROT)."""
    a = np.deg2rad(angrot)
    dx, dy = x - xorigin, y - yorigin
    return dx * np.cos(a) + dy * np.sin(a), -dx * np.sin(a) + dy * np.cos(a)


def structured_cell(delr: np.ndarray, delc: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """cell2d number (row * ncol + column; -1 outside) of model points (x, y) in a DIS grid: columns from x = 0
    rightwards, rows from the top edge y = sum(delc) downwards; a point on an edge goes to the lower row or
    column number, as in flopy's StructuredGrid.intersect."""
    xe = np.concatenate([[0.0], np.cumsum(delr)])
    ye = np.concatenate([[0.0], np.cumsum(delc)])              # distance from the top edge
    col = np.searchsorted(xe, x, side="left") - 1
    col[x == 0.0] = 0
    row = np.searchsorted(ye, ye[-1] - y, side="left") - 1
    row[y == ye[-1]] = 0
    inside = (col >= 0) & (col < len(delr)) & (row >= 0) & (row < len(delc))
    return np.where(inside, row * len(delr) + col, -1)


def polygon_cell(vertices: np.ndarray, iavert: np.ndarray, javert: np.ndarray, x: np.ndarray,
                 y: np.ndarray) -> np.ndarray:
    """cell2d number (-1 outside) of model points (x, y) among polygons (cell i: vertices javert[iavert[i]:
    iavert[i+1]], 0-based, the last may repeat the first), by the crossing-number test against the candidates of
    a bucket grid over the polygons' bounding boxes. A point on a shared edge goes to the lower cell number."""
    n = len(iavert) - 1
    counts = np.diff(iavert)
    width = int(counts.max())
    pad = np.repeat(javert[iavert[1:] - 1][:, None], width, axis=1)       # short polygons repeat their last vertex
    ragged = np.arange(width)[None, :] < counts[:, None]
    pad[ragged] = javert
    px, py = vertices[pad, 0], vertices[pad, 1]                          # (n, width)
    lo = np.stack([px.min(axis=1), py.min(axis=1)], axis=1)
    hi = np.stack([px.max(axis=1), py.max(axis=1)], axis=1)
    nb = max(1, int(np.sqrt(n)))
    origin, size = lo.min(axis=0), np.maximum(hi.max(axis=0) - lo.min(axis=0), 1e-300)

    def bucket(p):
        return np.clip(((p - origin) / size * nb).astype(np.int64), 0, nb - 1)

    b0, b1 = bucket(lo), bucket(hi)
    span = b1 - b0 + 1
    per_cell = span[:, 0] * span[:, 1]
    cell = np.repeat(np.arange(n), per_cell)
    k = np.arange(per_cell.sum()) - np.repeat(np.cumsum(per_cell) - per_cell, per_cell)
    bx = b0[cell, 0] + k % span[cell, 0]
    by = b0[cell, 1] + k // span[cell, 0]
    key = bx * nb + by
    order = np.lexsort((cell, key))
    key, cell = key[order], cell[order]
    start = np.searchsorted(key, np.arange(nb * nb + 1))
    out = np.full(len(x), -1, dtype=np.int64)
    pts = np.stack([x, y], axis=1)
    qb = bucket(pts)
    qkey = qb[:, 0] * nb + qb[:, 1]
    nc = start[qkey + 1] - start[qkey]
    point = np.repeat(np.arange(len(x)), nc)
    cand = cell[np.repeat(start[qkey], nc) + np.arange(nc.sum()) - np.repeat(np.cumsum(nc) - nc, nc)]
    hit = _inside_polygons(px[cand], py[cand], x[point], y[point])
    point, cand = point[hit], cand[hit]
    first = np.lexsort((cand, point))
    point, cand = point[first], cand[first]
    keep = np.concatenate([[True], point[1:] != point[:-1]]) if len(point) else np.zeros(0, bool)
    out[point[keep]] = cand[keep]
    return out


def _inside_polygons(px: np.ndarray, py: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Crossing-number test of point i against polygon i (rows of px, py), boundary included."""
    qx, qy = np.roll(px, -1, axis=1), np.roll(py, -1, axis=1)
    xs, ys = x[:, None], y[:, None]
    straddle = (py > ys) != (qy > ys)
    with np.errstate(divide="ignore", invalid="ignore"):
        xcross = px + (ys - py) * (qx - px) / (qy - py)
    crossings = np.sum(straddle & (xs < xcross), axis=1)
    # on an edge: collinear with it and within its box
    cross = (qx - px) * (ys - py) - (qy - py) * (xs - px)
    scale = np.abs(qx - px) + np.abs(qy - py)
    on_edge = (np.abs(cross) <= 1e-12 * scale * scale) & (xs >= np.minimum(px, qx)) & (xs <= np.maximum(px, qx)) \
        & (ys >= np.minimum(py, qy)) & (ys <= np.maximum(py, qy))
    return (crossings % 2 == 1) | np.any(on_edge & (scale > 0), axis=1)


def layer_of(top: np.ndarray, botm: np.ndarray, cell2d: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Layer (0 = top; -1 above the top or below the bottom) of points at elevations z in columns cell2d (-1:
    none): botm[k] < z <= top of layer k (the model's top for layer 0, botm[k-1] below)."""
    c = np.maximum(cell2d, 0)
    tops = np.vstack([top[None, :], botm[:-1]])[:, c]          # (nlay, n)
    bots = botm[:, c]
    within = (bots < z[None, :]) & (z[None, :] <= tops)
    k = np.where(within.any(axis=0), np.argmax(within, axis=0), -1)
    return np.where(cell2d >= 0, k, -1)


def regular_grid_weights(axes: list, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Multilinear interpolation on a regular grid of nodes: ``axes`` the increasing node coordinates along x,
    y (and z), the values flat in C order over (z,) y, x; ``points`` (n, 2 or 3). Outside the grid's box:
    index -1."""
    dims = len(axes)
    per_axis = []
    inside = np.ones(len(points), bool)
    for d, ax in enumerate(axes):
        p = points[:, d]
        inside &= (p >= ax[0]) & (p <= ax[-1])
        if len(ax) == 1:
            per_axis.append((np.zeros(len(p), np.int64), np.zeros(len(p), np.int64), np.ones(len(p)), len(ax)))
            continue
        i = np.clip(np.searchsorted(ax, p, side="right") - 1, 0, len(ax) - 2)
        t = np.clip((p - ax[i]) / (ax[i + 1] - ax[i]), 0.0, 1.0)
        per_axis.append((i, i + 1, t, len(ax)))
    shape = [len(ax) for ax in axes][::-1]                      # values are (z,) y, x
    strides = np.cumprod([1] + shape[::-1][:-1])                # stride of x, y, z in the flat array
    index, weight = [], []
    for corner in range(2 ** dims):
        idx = np.zeros(len(points), np.int64)
        w = np.ones(len(points))
        for d, (i0, i1, t, _) in enumerate(per_axis):
            up = (corner >> d) & 1
            idx += (i1 if up else i0) * strides[d]
            w *= t if up else 1.0 - t
        index.append(idx)
        weight.append(w)
    index, weight = np.stack(index, axis=1), np.stack(weight, axis=1)
    index[~inside] = -1
    return index, weight


def scattered_weights(nodes: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation on the Delaunay triangulation of scattered ``nodes`` (m, 2) at ``points`` (n, 2):
    barycentric weights of the containing triangle; outside the nodes' convex hull: index -1."""
    from matplotlib.tri import Triangulation
    tri = Triangulation(nodes[:, 0], nodes[:, 1])
    which = tri.get_trifinder()(points[:, 0], points[:, 1])
    t = tri.triangles[np.maximum(which, 0)]
    a, b, c = nodes[t[:, 0]], nodes[t[:, 1]], nodes[t[:, 2]]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1 = ((points[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (points[:, 1] - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (points[:, 1] - a[:, 1]) - (points[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    weight = np.stack([1.0 - l1 - l2, l1, l2], axis=1)
    index = t.astype(np.int64)
    index[which < 0] = -1
    return index, weight
