"""The output steps of a run, from each rank's values of its local mesh: the volume fields (``fields.h5``),
the faults' per-face fields (``fault.h5``) and the land surface (``surface.h5``) with its earth-fissure hazard
maxima.

On more than one rank with h5py built with MPI, the volume and fault fields are written by every rank, each
its own rows (pfault.io.parallel); otherwise they are gathered to rank 0 in the serial numbering and written
there. The land-surface series and the hazard maxima are computed and written on rank 0 either way: the
surface is 2-D and small, and only its vertices' displacements are gathered.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import run_on_root
from ..mesh import distributed
from ..mesh.fault import copy_index, vertex_copies
from .parallel import ParallelSeries, Rows, agree_shapes, as_columns

if TYPE_CHECKING:
    from ..mesh.distributed import LocalMesh


@dataclass
class LocalStep:
    """One output step's values on this rank."""
    displacement: np.ndarray        # (nv, 3 * max sides) per local vertex: its sides (pieces) in order, side 0
                                    # repeated where a vertex has fewer
    head: np.ndarray | None         # (nv,) head change (groundwater flow), or None
    cells: dict                     # per local cell: {name: (nc, ...)}
    faces: dict                     # per fault face this rank owns (``faces`` of StepOutput): {name: (nf, ...)}; the
                                    # fault series' (fault.h5), written where the mesh has fault faces


class StepOutput:
    """Writes output steps through ``writer`` (pfault.io.output.RunWriter, rank 0). ``vert_sides``: the sides
    (pieces) of every serial vertex, None without faults (the output mesh has a copy of each piece but the first
    after the serial vertices, pfault.mesh.fault.vertex_copies); ``max_sides`` the columns of a LocalStep's
    displacement over 3; ``faces``: the serial ids of the fault faces this rank owns and ``fault_id`` the fault of every
    face (empty without faults: no fault series). Every method is collective."""

    def __init__(self, comm: Any, mesh: LocalMesh, writer: Any, vert_sides: np.ndarray | None, max_sides: int,
                 faces: np.ndarray, fault_id: np.ndarray, parallel: bool = False) -> None:
        self.comm, self.mpi = comm, comm.tompi4py()
        self.mesh, self.writer = mesh, writer
        n = mesh.n_global_vertices
        self.vert_sides = np.ones(n, np.int64) if vert_sides is None else np.asarray(vert_sides, dtype=np.int64)
        self.copies, self.faces = vertex_copies(self.vert_sides), faces
        self.parallel, self.max_sides = bool(parallel), int(max_sides)
        self.n_faces = len(fault_id)
        self.series = {}
        if not parallel:
            return
        nv = len(mesh.vert_serial)
        own = np.flatnonzero(mesh.vert_owned)
        rows, take = [mesh.vert_serial[own]], [own]
        for piece in range(1, max_sides):
            at = own[mesh.vert_sides[own] > piece]
            rows.append(n + copy_index(self.vert_sides, mesh.vert_serial[at], piece))
            take.append(piece * nv + at)
        self.vertices = Rows(np.concatenate(rows), n + len(self.copies[0]), np.concatenate(take))
        self.cells = Rows(mesh.cell_serial, mesh.n_global_cells)
        rows = {"fields": {"Node": self.vertices, "Cell": self.cells}}
        if self.n_faces:
            self.face_rows = Rows(faces, self.n_faces)
            rows["fault"] = {"Cell": self.face_rows}
            self.fault_id = np.asarray(fault_id, dtype=np.int64)[faces]
        run_on_root(comm, lambda: writer.release(list(rows)))      # writer: rank 0 only
        directory = self.mpi.bcast(writer.dir if self.mpi.rank == 0 else None, root=0)
        for name, by_center in rows.items():
            self.series[name] = ParallelSeries(comm, directory, name, by_center)

    def write(self, step: int, t: float, values: LocalStep, surface: Any = None) -> None:
        """Write one step (LocalStep ``values``, and the land surface's step ``surface``, pfault.surface.SurfaceStep,
        on rank 0: None elsewhere or without a land surface)."""
        write = self._write_parallel if self.parallel else self._write_gathered
        values = LocalStep(values.displacement, values.head, agree_shapes(self.mpi, values.cells),
                           agree_shapes(self.mpi, values.faces) if self.n_faces else {})
        write(step, t, values, surface)

    def _write_parallel(self, step, t, values, surface):
        nv = len(values.displacement)
        disp = values.displacement.reshape(nv, self.max_sides, 3).transpose(1, 0, 2).reshape(-1, 3)
        point = {"displacement": disp}
        if values.head is not None:
            point["head_change"] = np.tile(values.head, len(disp) // max(len(values.head), 1))
        cells = {"material": self.mesh.cell_material}
        cells.update(values.cells)
        entries = {"fields": self.series["fields"].write_step(step, t, point, cells)}
        if self.n_faces:
            faces = {"fault": self.fault_id}
            faces.update(values.faces)
            entries["fault"] = self.series["fault"].write_step(step, t, None, faces)

        def write():
            self.writer.add_steps(entries)
            self._surface_step(step, t, surface)
        run_on_root(self.comm, write)        # a failure to write ends every rank

    def _write_gathered(self, step, t, values, surface):
        mesh = self.mesh
        both = distributed.gather_vertex_values(mesh, values.displacement)
        head = None if values.head is None else distributed.gather_vertex_values(mesh, values.head.reshape(-1, 1))
        names = list(values.cells)
        columns = [as_columns(values.cells[k]) for k in names]
        stacked = distributed.gather_cell_values(mesh, np.concatenate(columns, axis=1))
        faces = self.mpi.gather((self.faces, values.faces), root=0) if self.n_faces else None

        def write():
            vertex, piece = self.copies
            u = np.concatenate([both[:, :3], both.reshape(len(both), self.max_sides, 3)[vertex, piece]])
            point_data = {"displacement": u}
            if head is not None:
                point_data["head_change"] = np.concatenate([head[:, 0], head[vertex, 0]])
            cell_data, start = {}, 0
            for k, c in zip(names, columns):
                block = stacked[:, start:start + c.shape[1]]
                cell_data[k] = block[:, 0] if values.cells[k].ndim == 1 else block
                start += c.shape[1]
            self.writer.write_step(step, t, point_data, cell_data)
            if self.n_faces:
                self.writer.write_fault_step(step, t, _by_face(faces, self.n_faces))
            self._surface_step(step, t, surface)
        run_on_root(self.comm, write)        # a failure to write ends every rank

    def _surface_step(self, step, t, surface):
        """Land-surface fields of one output step (rank 0): displacement and the earth-fissure hazard fields."""
        if surface is not None:
            self.writer.write_surface_step(step, t, {"displacement": surface.displacement, **surface.points},
                                           surface.fields)

    def close(self) -> None:
        for series in self.series.values():
            series.close()
        self.series = {}


def _by_face(parts, n_faces):
    """[(face ids, {name: values})] of every rank -> {name: values of all faces in serial order}."""
    out = {}
    for key in parts[0][1]:
        first = np.asarray(parts[0][1][key])
        out[key] = np.zeros((n_faces,) + first.shape[1:], dtype=first.dtype)
        for faces, data in parts:
            out[key][faces] = data[key]
    return out
