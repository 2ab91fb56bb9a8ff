#!/usr/bin/env python
"""Sizes and meshing times of the built-in case-study meshes against the paper (Franceschini et al. 2015).

    .venv/bin/python benchmarks/mesh_sizes.py [size_factor ...]      (default: 1 2)

For each mesh and size factor prints nodes, tetrahedra and fault (fissure) triangles, their deviation
from the paper's mesh (at size factor 1; at other factors "/k" means k times fewer than the paper), and
the wall time of building the mesh (gmsh geometry, meshing
and conversion to a SerialMesh). A JSON line with all figures ends the output.
"""
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from pfault.mesh.geometry import queretaro_mesh, wuxi_mesh  # noqa: E402

PAPER = {"wuxi": (wuxi_mesh, "fissure", (23303, 121942, 1876)),
         "queretaro": (queretaro_mesh, "fault", (57050, 297971, 8074))}


def main(factors):
    rows = []
    print(f"{'mesh':<10} {'factor':>6} {'nodes':>9} {'paper':>7} {'dev':>7} {'tets':>9} {'paper':>8} {'dev':>7} "
          f"{'fault':>6} {'paper':>6} {'dev':>7} {'wall s':>7}")
    for name, (build, fault, paper) in PAPER.items():
        for f in factors:
            t0 = time.perf_counter()
            mesh = build(f)
            wall = time.perf_counter() - t0
            got = (len(mesh.points), len(mesh.tets), len(mesh.surfaces[fault]))
            # deviation from the paper at size factor 1; elsewhere how many times fewer (or more) than the paper
            dev = [f"{100.0 * (g / p - 1.0):+6.1f}%" if f == 1.0 else f"/{p / g:.2f}" for g, p in zip(got, paper)]
            rows.append({"mesh": name, "size_factor": f, "nodes": got[0], "tets": got[1], "fault_faces": got[2],
                         "paper": dict(zip(("nodes", "tets", "fault_faces"), paper)), "wall_s": round(wall, 2)})
            print(f"{name:<10} {f:>6g} {got[0]:>9d} {paper[0]:>7d} {dev[0]:>7} {got[1]:>9d} {paper[1]:>8d} "
                  f"{dev[1]:>7} {got[2]:>6d} {paper[2]:>6d} {dev[2]:>7} {wall:>7.2f}", flush=True)
    print(json.dumps(rows))


if __name__ == "__main__":
    main([float(a) for a in sys.argv[1:]] or [1.0, 2.0])
