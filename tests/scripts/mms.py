#!/usr/bin/env python
"""Manufactured solution on the unit cube: u = c sin(pi x) sin(pi y) sin(pi z), fixed boundary.

Prints JSON {"h": [...], "l2": [...], "h1": [...]} for meshes n = 4, 8, 16 (or argv[1:] sizes).
"""
import json
import sys

import petsc4py

petsc4py.init([sys.argv[0], "-ksp_type", "preonly", "-pc_type", "lu", "-pc_factor_mat_solver_type", "mumps"])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault import fields  # noqa: E402
from pfault.assembly.elastic import ElasticAssembler  # noqa: E402
from pfault.materials.properties import CellProperties  # noqa: E402
from pfault.mesh import distributed  # noqa: E402
from pfault.mesh.box import box_mesh  # noqa: E402
from pfault.physics import elasticity as el  # noqa: E402
from pfault.physics.loading import MaterialDrawdown  # noqa: E402
from pfault.scene import Material  # noqa: E402
from pfault.solver.equations import Equations  # noqa: E402
from pfault.sources import TableSource  # noqa: E402

E, NU = 1.0e7, 0.3
C = np.array([1.0, -0.5, 0.75]) * 1e-2
LAM, MU = el.lame(E, NU)
PI = np.pi
# 4-point degree-2 rule on the reference tetrahedron (barycentric)
A, B = 0.5854101966249685, 0.1381966011250105
BARY = np.array([[A, B, B, B], [B, A, B, B], [B, B, A, B], [B, B, B, A]])
W = np.full(4, 0.25)


def exact(x):
    phi = np.sin(PI * x[..., 0]) * np.sin(PI * x[..., 1]) * np.sin(PI * x[..., 2])
    return phi[..., None] * C


def exact_grad(x):
    s = np.sin(PI * x)
    c = np.cos(PI * x)
    g = PI * np.stack([c[..., 0] * s[..., 1] * s[..., 2], s[..., 0] * c[..., 1] * s[..., 2],
                       s[..., 0] * s[..., 1] * c[..., 2]], axis=-1)
    return C[:, None] * g[..., None, :]  # du_i/dx_j


def body_force(x):
    """b = -div sigma = -[(lam + mu) H c + mu lap(phi) c]."""
    s = np.sin(PI * x)
    c = np.cos(PI * x)
    phi = s[..., 0] * s[..., 1] * s[..., 2]
    H = np.empty(x.shape[:-1] + (3, 3))
    for i in range(3):
        for j in range(3):
            if i == j:
                H[..., i, j] = -PI ** 2 * phi
            else:
                k = 3 - i - j
                H[..., i, j] = PI ** 2 * c[..., i] * c[..., j] * s[..., k]
    lap = -3 * PI ** 2 * phi
    return -((LAM + MU) * np.einsum("...ij,j->...i", H, C) + MU * lap[..., None] * C)


def solve(n):
    comm = PETSc.COMM_WORLD
    serial = box_mesh((1.0, 1.0, 1.0), (n, n, n), zs=np.linspace(0, 1, n + 1)) if comm.rank == 0 else None
    mask = np.full(len(serial.points), 0, np.int64) if serial is not None else None
    if serial is not None:
        for tri in serial.surfaces.values():
            mask[np.unique(tri)] = 7
    mesh = distributed.build(comm, serial, vert_constraint=mask)
    dofmap = fields.build(mesh)
    asm = ElasticAssembler(mesh, dofmap, CellProperties.of_cells([Material("soil", E, NU, 1.0, 2000.0)],
                                                                 mesh.cell_material))
    prob = Equations(mesh, dofmap, asm, [], TableSource(MaterialDrawdown([None]), mesh.cell_material), None)
    u = prob.create_vec()
    x = mesh.coords[mesh.cells]                       # (nc,4,3)
    xq = np.einsum("qa,nai->nqi", BARY, x)            # (nc,4q,3)
    bq = body_force(xq)
    fe = np.einsum("q,n,qa,nqi->nai", W, asm.vol, BARY, bq)
    asm.scatter_cell_forces(fe, prob.loads.static_local)
    prob.loads.set(0.0)
    ksp = PETSc.KSP().create(comm=comm)
    ksp.setOperators(prob.K, prob.K)
    ksp.setFromOptions()
    ksp.solve(prob.loads.f, u)
    u_vec, u = u, prob.local_array(u)
    u_vec.destroy()
    ue = asm.cell_displacements(u)                    # (nc,4,3)
    uq = np.einsum("qa,nai->nqi", BARY, ue)
    err = uq - exact(xq)
    l2 = np.einsum("q,n,nqi->", W, asm.vol, err ** 2)
    gh = np.einsum("nai,naj->nij", ue, asm.grad)      # constant per cell
    gerr = gh[:, None] - exact_grad(xq)
    h1 = np.einsum("q,n,nqij->", W, asm.vol, gerr ** 2)
    mpi = comm.tompi4py()
    l2, h1 = mpi.allreduce(l2), mpi.allreduce(h1)
    ksp.destroy()
    prob.destroy()
    mesh.dm.destroy()
    return float(np.sqrt(l2)), float(np.sqrt(h1))


if __name__ == "__main__":
    sizes = [int(a) for a in sys.argv[1:]] or [4, 8, 16]
    out = {"h": [1.0 / n for n in sizes], "l2": [], "h1": []}
    for n in sizes:
        l2, h1 = solve(n)
        out["l2"].append(l2)
        out["h1"].append(h1)
    if PETSc.COMM_WORLD.rank == 0:
        print(json.dumps(out))
