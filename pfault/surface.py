"""The land surface as a measured part of the run: its displacement gathered on rank 0 at output steps, the
earth-fissure hazard fields of that displacement (pfault.hazard) and their maxima, which go into the step's
record; surface.h5 writes the same fields (pfault.io.steps)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from . import hazard
from .errors import run_on_root
from .mesh.fault import copy_index, output_mesh


@dataclass(frozen=True)
class SurfaceStep:
    """The land surface at an output step (rank 0): its vertices' displacement, its hazard fields (per triangle)
    and the terms' fields per vertex (``points``: a soil's inelastic and elastic subsidence, critical heads)."""
    displacement: np.ndarray
    fields: dict
    points: dict = field(default_factory=dict)


class LandSurface:
    """The land surface of ``model`` (the triangles of -pfault_ground_surface on the output mesh, or those at its
    top: pfault.hazard.land_surface; ``surface`` on rank 0, None when there is none), the output-mesh rows of
    this rank's owned vertices and pieces on it, and what the equations' terms measure along the vertical columns
    under its vertices (``columns``: (term index, the term's columns), pfault.solver.terms). Collective."""

    def __init__(self, model: Any) -> None:
        self.comm, self.mpi = model.comm, model.comm.tompi4py()
        self.surface = run_on_root(self.comm, _land_surface, model)
        vertices = self.mpi.bcast(None if self.surface is None else self.surface.vertices, root=0)
        self.vertices = vertices
        self.columns: list = []
        if vertices is None:
            return
        xy = self.mpi.bcast(None if self.surface is None else self.surface.points[:, :2], root=0)
        for k, term in enumerate(model.equations.terms):
            columns = term.columns(xy, model.mesh)
            if columns is not None:
                self.columns.append((k, columns))
        mesh, dofmap = model.mesh, model.dofmap
        sides = self.mpi.bcast(model.split.vert_sides if self.comm.rank == 0 and model.split is not None
                               else np.ones(mesh.n_global_vertices, np.int64) if self.comm.rank == 0 else None)
        own = np.flatnonzero(mesh.vert_owned)
        rows, take = [mesh.vert_serial[own]], [np.column_stack([own, np.zeros(len(own), np.int64)])]
        for piece in range(1, dofmap.max_sides):
            at = own[mesh.vert_sides[own] > piece]
            rows.append(mesh.n_global_vertices + copy_index(sides, mesh.vert_serial[at], piece))
            take.append(np.column_stack([at, np.full(len(at), piece)]))
        rows, take = np.concatenate(rows), np.concatenate(take)
        on = np.isin(rows, vertices)
        self.rows, self.take = rows[on], take[on]

    def measure(self, both: np.ndarray, terms: tuple = ()) -> tuple[dict, SurfaceStep | None]:
        """The hazard maxima of the displacement ``both`` (local vertices x 3 per side, relative to the initial
        state) and the terms' figures on every rank, and the surface's step on rank 0 (None elsewhere and without a
        land surface). ``terms``: the state's local array, the terms' loads and histories, for the terms'
        columns. Collective."""
        if self.vertices is None:
            return {}, None
        u = both.reshape(len(both), both.shape[1] // 3, 3)[self.take[:, 0], self.take[:, 1]]
        parts = self.mpi.gather((self.rows, u), root=0)
        res = run_on_root(self.comm, self._step, parts)
        hz = self.mpi.bcast(res[0] if res is not None else None, root=0)
        step = res[1] if res is not None else None
        for k, columns in self.columns:
            x_loc, loads, histories = terms
            figures, points = columns.surface(x_loc, loads[k], histories[k],
                                              None if step is None else step.displacement)
            hz.update(figures)
            if step is not None:
                step = replace(step, points={**step.points, **points})
        return hz, step

    def _step(self, parts: list) -> tuple[dict, SurfaceStep]:
        surf = self.surface
        u = np.zeros((len(surf.vertices), 3))
        for rows, values in parts:
            u[np.searchsorted(surf.vertices, rows)] = values
        fields = hazard.surface_fields(surf.points, surf.triangles, u)
        out = hazard.maxima(surf.points, surf.triangles, fields)
        out.update(hazard.fissure_prone(surf.points, surf.triangles, u, surf.strain_threshold))
        return out, SurfaceStep(u, fields)


def _land_surface(model: Any) -> hazard.Surface | None:
    points, tets = output_mesh(model.serial.points, model.serial.tets, model.split)
    s = model.settings
    return hazard.land_surface(points, tets, model.serial, model.split, s.ground_surface,
                               s.hazard_strain_threshold)
