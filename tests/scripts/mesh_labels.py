#!/usr/bin/env python
"""Point data through DMPlexDistribute as DMLabels (pfault.mesh.distributed.build), on any number of ranks.

    mpirun -n 2 python tests/scripts/mesh_labels.py

A unit box (8x8x8 hexahedra, 3072 tetrahedra) with three materials at random, a fault through the whole box
(x = 0.25) and a buried one (x = 0.75, with tips), and boundary data drawn at random (seeded) so that cells carry
several tagged faces and vertices every constraint bit. Prints JSON:

- "labels": for every label of pfault.mesh.distributed.LABELS, {value: number of points} over all ranks (every
  cell, owned vertices), and "serial_labels" the same for the mesh built on one rank;
- "mismatch": per LocalMesh array, the number of local rows (ghost vertices too) that differ from the serial
  input at the row's serial id, and "missing": serial cells and vertices that no rank has;
- "fault_faces": how often each fault face is some rank's (1: once), "face_vertices": local fault faces whose
  vertices are not the serial face's, "minus_side" / "plus_side": fault-face corners where the minus cell uses
  plus-side dofs / the plus cell does not use them at a split vertex (gathered, serial numbering);
- "multi_valued": cells with more than one boundary face, "ranks".
"""
import json
import sys

import numpy as np
import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402

from pfault.mesh import distributed  # noqa: E402
from pfault.mesh.box import box_mesh, parse_planes  # noqa: E402
from pfault.mesh.fault import split_faults  # noqa: E402
from pfault.mesh.serial import TET_FACES, boundary_faces  # noqa: E402


def inputs():
    """The serial mesh and the per-point arrays build() is given (rank 0)."""
    rng = np.random.default_rng(7)
    serial = box_mesh((1.0, 1.0, 1.0), (8, 8, 8), planes=parse_planes(["a:x:0.25", "b:x:0.75:0.25:0.75:-0.75:-0.25"]))
    nc, nv = len(serial.tets), len(serial.points)
    serial.cell_material = rng.integers(0, 3, nc)
    split = split_faults(serial, ["a", "b"])
    face_tag = np.full((nc, 4), -1, np.int64)
    cell, lface = boundary_faces(serial.tets, nv)
    face_tag[cell, lface] = rng.integers(-1, 3, len(cell))
    mask = rng.integers(0, 16, nv) * (rng.random(nv) < 0.5)
    ground = np.column_stack([rng.random(nv) < 0.3, rng.integers(-1, 3, nv)]).astype(np.int64)
    return serial, dict(cell_face_tag=face_tag, vert_constraint=mask, vert_ground=ground, split=split)


def label_counts(mesh):
    """{label: {value: number of this rank's points}}: every cell, owned vertices only."""
    dm = mesh.dm
    keep = np.r_[np.ones(mesh.v_start, bool), mesh.vert_owned]
    out = {}
    for name in distributed.LABELS:
        label = dm.getLabel(name)
        values = label.getValueIS()
        out[name] = {}
        for value in values.getIndices():
            stratum = label.getStratumIS(value)
            out[name][int(value)] = int(keep[stratum.getIndices()].sum())
            stratum.destroy()
        values.destroy()
    return out


def merge(counts):
    total = {}
    for rank_counts in counts:
        for name, strata in rank_counts.items():
            for value, n in strata.items():
                total.setdefault(name, {})
                total[name][str(value)] = total[name].get(str(value), 0) + n
    return {name: {v: n for v, n in strata.items() if n} for name, strata in total.items()}


def expected(serial, kw):
    """Serial cell and vertex arrays in LocalMesh's layout."""
    split = kw["split"]
    fault_face = np.full((len(serial.tets), 4), -1, np.int64)
    fault_face[split.minus_cell, split.minus_lface] = np.arange(len(split.faces))
    vert_data = np.column_stack([kw["vert_constraint"], kw["vert_ground"][:, 0], split.vert_sides,
                                 kw["vert_ground"][:, 1]])
    cells = np.column_stack([serial.cell_material, kw["cell_face_tag"], split.cell_side, fault_face])
    return cells, vert_data


def local_rows(mesh):
    cells = np.column_stack([mesh.cell_material, mesh.cell_face_tag, mesh.cell_side, mesh.cell_fault_face])
    return cells, mesh.vert_data


def main():
    comm = PETSc.COMM_WORLD
    mpi = comm.tompi4py()
    serial, kw = inputs() if comm.rank == 0 else (None, dict(cell_face_tag=None, vert_constraint=None,
                                                                vert_ground=None, split=None))
    mesh = distributed.build(comm, serial, **kw)
    cells, verts = local_rows(mesh)
    faces = np.nonzero(mesh.cell_fault_face >= 0)
    face_ids = mesh.cell_fault_face[faces]
    face_verts = mesh.vert_serial[mesh.cells[faces[0][:, None], TET_FACES[faces[1]]]]
    gathered = mpi.gather((label_counts(mesh), mesh.cell_serial, cells, mesh.vert_serial, verts, face_ids,
                           face_verts))
    if comm.rank == 0:
        one = distributed.build(PETSc.COMM_SELF, serial, **kw)
        want_cells, want_verts = expected(serial, kw)
        split = kw["split"]
        mismatch = {"cells": 0, "vertices": 0}
        seen_cells, seen_verts = np.zeros(len(serial.tets), bool), np.zeros(len(serial.points), bool)
        side = np.zeros((len(serial.tets), 4), np.int64)
        bad_faces = 0
        for _, cid, c, vid, v, fid, fv in gathered:
            mismatch["cells"] += int(np.any(c != want_cells[cid], axis=1).sum())
            mismatch["vertices"] += int(np.any(v != want_verts[vid], axis=1).sum())
            seen_cells[cid], seen_verts[vid] = True, True
            side[cid] = c[:, 5:9]
            bad_faces += int(np.any(np.sort(fv, axis=1) != np.sort(split.faces[fid], axis=1), axis=1).sum())
        minus = side[split.minus_cell[:, None], TET_FACES[split.minus_lface]]
        plus_corners = serial.tets[split.plus_cell[:, None], TET_FACES[split.plus_lface]]
        plus = side[split.plus_cell[:, None], TET_FACES[split.plus_lface]]
        print(json.dumps({
            "ranks": comm.size,
            "labels": merge([g[0] for g in gathered]),
            "serial_labels": merge([label_counts(one)]),
            "mismatch": mismatch,
            "missing": int((~seen_cells).sum() + (~seen_verts).sum()),
            "fault_faces": np.bincount(np.concatenate([g[5] for g in gathered]),
                                       minlength=len(split.faces)).tolist(),
            "face_vertices": bad_faces,
            "minus_side": int(minus.sum()),
            "plus_side": int(((split.vert_sides[plus_corners] == 2) & (plus != 1)).sum()),
            "multi_valued": int(((kw["cell_face_tag"] >= 0).sum(axis=1) > 1).sum()),
        }))
        one.dm.destroy()
    if mesh.migration is not None:
        mesh.migration.destroy()
    mesh.dm.destroy()


if __name__ == "__main__":
    main()
