"""The materials with memory measured along vertical columns: under the land surface's points and under the
stations, each layer's compaction (its cells' vertical strains integrated down the column, m) and its critical head
and margin (m: their means over the length the column runs in the layer), of the cells' values recovered at their
vertices (``SoilColumns``).

A column is the vertical line through a point (x, y): each cell it crosses adds its value times the length of the
line inside it (the chord, from the cell's barycentric coordinates, which are affine along the line). A point on a
vertex or an edge of the mesh puts the line on faces shared by several cells; it is moved by 1e-9 of the mesh's
extent towards the mesh's centre (turned by 0.1 rad off that direction, so that it does not run along a mesh line),
where the line crosses the interiors of the cells: the chords then change by that much. Each rank integrates its
cells; rank 0 sums. The inelastic subsidence of a land-surface point is the inelastic compaction of its column; the
elastic subsidence is the rest of its subsidence.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from mpi4py import MPI

from .measures import column_sums, per_cell

NUDGE = 1e-9            # the shift of a column off mesh vertices and edges, relative to the mesh's extent
TURN = 0.1              # rad: the shift's turn off the direction to the mesh's centre


def segments(points: np.ndarray, corners: np.ndarray, grad: np.ndarray) -> tuple[np.ndarray, ...]:
    """(point, cell, z_low, z_high) of every vertical line through ``points`` (m, 2) that crosses a tetrahedron
    (``corners`` (n, 4, 3), shape-function gradients ``grad`` (n, 4, 3)): where the line enters and leaves it."""
    none = np.zeros(0, np.int64)
    if not len(points) or not len(corners):
        return none, none, np.zeros(0), np.zeros(0)
    from scipy.spatial import cKDTree       # (0.3 s to import: only scenes with soils that remember come here)
    lo, hi = corners[:, :, :2].min(axis=1), corners[:, :, :2].max(axis=1)
    found = cKDTree(points).query_ball_point(0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo, axis=1) * (1 + 1e-9))
    count = np.array([len(f) for f in found], dtype=np.int64)
    cell = np.repeat(np.arange(len(corners)), count)
    point = np.concatenate([np.asarray(f, np.int64) for f in found if len(f)] or [none])
    g, x = grad[cell], corners[cell]                                     # lambda_i = 1 + g_i . (p - X_i)
    c = 1.0 + np.einsum("nik,nik->ni", g[:, :, :2], points[point][:, None, :] - x[:, :, :2]) - g[:, :, 2] * x[:, :, 2]
    gz = g[:, :, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = -c / gz
    zlo = np.where(gz > 0, bound, -np.inf).max(axis=1)
    zhi = np.where(gz < 0, bound, np.inf).min(axis=1)
    keep = ~np.any((gz == 0) & (c < 0), axis=1) & np.isfinite(zlo) & np.isfinite(zhi) & (zhi > zlo)
    return point[keep], cell[keep], zlo[keep], zhi[keep]


def _extent(coords: np.ndarray, mpi: Any) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's box in x, y on every rank (collective)."""
    lo, hi = coords[:, :2].min(axis=0, initial=np.inf), coords[:, :2].max(axis=0, initial=-np.inf)
    mpi.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    mpi.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    return lo, hi


def nudged(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``points`` (m, 2) moved by NUDGE of the extent of the box [lo, hi] towards its centre, turned by TURN."""
    d = 0.5 * (lo + hi) - points
    d = np.where(np.linalg.norm(d, axis=1)[:, None] > 0, d, [1.0, 0.0])
    c, s = np.cos(TURN), np.sin(TURN)
    d = np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]])
    return points + NUDGE * float(np.max(hi - lo)) * d / np.linalg.norm(d, axis=1)[:, None]


class SoilColumns:
    """The columns of the cells of the soil term ``term`` (pfault.soils.term.SoilTerm) under the points ``xy``
    (m, 2, mesh coordinates, the same on every rank) of the local mesh ``mesh``. Collective.

    A cell's values are first recovered at its vertices (the mean over the cells of the same layer around the
    vertex, on the same side of a fault, weighted by their volumes; every rank's cells) and the column integrates
    that continuous P1 field: P1 cells of a soil whose stiffness grows with depth share a load change unevenly (a
    cell's stress change differs from the 1-D one by up to half of it where cells are as tall as they are deep),
    and the mean over the cells around a vertex cancels most of it, as the mean over a horizontal slab of cells
    cancels all of it (equilibrium)."""

    def __init__(self, term: Any, xy: np.ndarray, mesh: Any) -> None:
        self.term, self.mpi = term, term.mpi
        soil = term.soil
        self.m, self.n_layers = len(xy), len(soil.layers)
        lo, hi = _extent(mesh.coords, self.mpi)
        corners = mesh.coords[mesh.cells[soil.cells]]
        self.point, self.cell, zlo, zhi = segments(nudged(np.asarray(xy, float), lo, hi), corners, term.grad)
        self.length = zhi - zlo
        self.slot = self.point * self.n_layers + soil.layer[self.cell]
        # barycentric coordinates of each chord's midpoint in its cell: lambda_i = 1 + g_i . (p - X_i)
        mid = np.column_stack([nudged(np.asarray(xy, float), lo, hi)[self.point], 0.5 * (zlo + zhi)])
        x, g = corners[self.cell], term.grad[self.cell]
        self.weights = 1.0 + np.einsum("nik,nik->ni", g, mid[:, None, :] - x)
        # each soil cell's vertices as keys of the recovery: (serial vertex, fault side, layer), over every rank
        sides = self.mpi.allreduce(int(mesh.cell_side.max(initial=0)), op=MPI.MAX) + 1
        key = ((mesh.vert_serial[mesh.cells[soil.cells]].astype(np.int64) * sides + mesh.cell_side[soil.cells])
               * self.n_layers + soil.layer[:, None])
        mpi_keys = np.unique(np.concatenate(self.mpi.allgather(np.unique(key))))
        self.key = np.searchsorted(mpi_keys, key)
        self.n_keys = len(mpi_keys)

    def recovered(self, values: np.ndarray) -> np.ndarray:
        """(n, 4, q): each soil cell's ``values`` (n, q) recovered at its vertices (the class's docstring)."""
        v = np.asarray(values, float).reshape(len(self.key), -1)
        w = self.term.vol
        sums = column_sums(self.key.ravel(), np.repeat(np.column_stack([w[:, None] * v, w]), 4, axis=0), self.n_keys)
        self.mpi.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        at = sums[self.key]                                   # (n, 4, q + 1)
        return at[:, :, :-1] / at[:, :, -1:]

    def along(self, values: np.ndarray) -> np.ndarray:
        """Per chord (pair), the P1 field of the recovered ``values`` (n, q) at the chord's midpoint: its mean over
        the chord (affine along it)."""
        return np.einsum("pa,paq->pq", self.weights, self.recovered(values)[self.cell])

    def integral(self, chord_values: np.ndarray) -> np.ndarray | None:
        """Per point and layer (m, layers, q) the column integral of ``chord_values`` (per chord, (pairs, q)) on
        rank 0 (None elsewhere)."""
        q = chord_values.shape[1]
        part = column_sums(self.slot, self.length[:, None] * chord_values, self.m * self.n_layers)
        total = np.zeros_like(part) if self.mpi.rank == 0 else None
        self.mpi.Reduce(part, total, op=MPI.SUM, root=0)
        return None if total is None else total.reshape(self.m, self.n_layers, q)

    def layers(self, x_loc: np.ndarray, load: Any, history: Any) -> dict | None:
        """Per point and layer (m, layers), rank 0 (None elsewhere): its elastic and inelastic compaction (m) and the
        critical head and head margin of the layer (m; their means over the column's length in it: a layer's
        critical head, as CSUB's interbed has one; NaN where the column does not cross the layer). Collective."""
        q = per_cell(self.term.soil, self.term.advanced(x_loc, history), load)
        names = ("compaction_elastic", "compaction_inelastic", "preconsolidation_head", "head_margin")
        chords = self.along(np.column_stack([q[n] for n in names]))
        sums = self.integral(np.column_stack([chords, np.ones(len(chords))]))
        if sums is None:
            return None
        length = sums[:, :, -1]
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(length[:, :, None] > 0, sums[:, :, 2:4] / length[:, :, None], np.nan)
        return {"compaction_elastic": sums[:, :, 0], "compaction_inelastic": sums[:, :, 1],
                "critical_head": mean[:, :, 0], "head_margin": mean[:, :, 1]}

    def surface(self, x_loc: np.ndarray, load: Any, history: Any, displacement: np.ndarray | None
                ) -> tuple[dict, dict]:
        """The land surface's figures (every rank: the largest inelastic and elastic subsidence, and both at the
        point of the largest subsidence, m) and point data (rank 0: subsidence_inelastic, subsidence_elastic, and per
        layer critical_head_<layer>, head_margin_<layer>), its points being the columns' and ``displacement`` (rank
        0) theirs. Collective."""
        lay = self.layers(x_loc, load, history)
        figures, points = None, {}
        if lay is not None:
            inelastic = lay["compaction_inelastic"].sum(axis=1)
            subsidence = -displacement[:, 2]
            elastic = subsidence - inelastic
            deepest = int(np.argmax(subsidence)) if len(subsidence) else 0
            points = {"subsidence_inelastic": inelastic, "subsidence_elastic": elastic}
            for k, name in enumerate(self.term.soil.names):
                points[f"critical_head_{name}"] = lay["critical_head"][:, k]
                points[f"head_margin_{name}"] = lay["head_margin"][:, k]
            at = (lambda v: float(v[deepest])) if len(subsidence) else (lambda v: 0.0)
            figures = {"max_subsidence_inelastic_m": float(inelastic.max(initial=0.0)),
                       "max_subsidence_elastic_m": float(elastic.max(initial=0.0)),
                       "subsidence_inelastic_at_max_m": at(inelastic), "subsidence_elastic_at_max_m": at(elastic)}
        return self.mpi.bcast(figures, root=0), points
