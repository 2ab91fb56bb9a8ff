#!/usr/bin/env python
"""A digest of every mesh array a scene builds, to show that a change to the mesh code leaves them as they were.

    mpirun -n 2 python tests/scripts/mesh_digest.py config/wuxi.opts -pfault_mesh_size_factor 4

Builds the scene's model (pfault.model.build_model: the serial mesh on rank 0, its boundary arrays and fault split,
the distributed mesh) and prints JSON: for each array, its dtype, shape and the SHA-256 of its bytes. "serial" holds
the serial mesh (points, tetrahedra, materials, every surface's triangles) and the fault split; "local" each rank's
LocalMesh arrays, in rank order. Two builds agree array for array when the two JSON outputs are equal.
"""
import hashlib
import json
import sys
import tempfile

import numpy as np
import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


scene = sys.argv[1]
out_dir = tempfile.mkdtemp(prefix="mesh_digest_")
petsc4py.init([sys.argv[0], *petsc_arguments(scene, []), "-pfault_output_dir", out_dir, *sys.argv[2:]])
from petsc4py import PETSc  # noqa: E402

from pfault.model import build_model  # noqa: E402
from pfault.options import OptionReader  # noqa: E402

LOCAL = ("coords", "cells", "cell_material", "cell_face_tag", "cell_side", "cell_fault_face", "vert_constraint",
         "vert_ground", "vert_sides", "vert_displacement_bc", "cell_serial", "vert_serial", "vert_owned")
SPLIT = ("vert_sides", "cell_side", "faces", "fault_id", "minus_cell", "minus_lface", "plus_cell", "plus_lface",
         "normal", "area", "tip_vertices")


def digest(a):
    a = np.ascontiguousarray(a)
    return f"{a.dtype} {a.shape} {hashlib.sha256(a.tobytes()).hexdigest()}"


def main():
    comm = PETSc.COMM_WORLD
    model = build_model(comm, OptionReader(PETSc), scene)
    mesh = model.mesh
    local = {name: digest(getattr(mesh, name)) for name in LOCAL}
    local.update(v_start=mesh.v_start, n_global_vertices=mesh.n_global_vertices,
                 n_global_cells=mesh.n_global_cells)
    gathered = comm.tompi4py().gather(local)
    if comm.rank == 0:
        serial, split = model.serial, model.split
        out = {"points": digest(serial.points), "tets": digest(serial.tets),
               "cell_material": digest(serial.cell_material), "material_names": serial.material_names}
        out.update({f"surface {name}": digest(tri) for name, tri in sorted(serial.surfaces.items())})
        if split is not None:
            out.update({f"split {name}": digest(getattr(split, name)) for name in SPLIT})
            out["split names"] = list(split.names)
        print(json.dumps({"ranks": comm.size, "serial": out, "local": gathered}, sort_keys=True))
    model.destroy()


if __name__ == "__main__":
    main()
