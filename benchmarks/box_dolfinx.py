#!/usr/bin/env python
"""The elastic box of box_assembly.py solved by DOLFINx (Debian's python3-dolfinx), for a side-by-side figure.

    mpirun -n 2 .venv/bin/python benchmarks/box_dolfinx.py [--cells 55] [--solver gamg] [-- PETSc options]

Same geometry (2000 m x 2000 m x 200 m, n x n x n hexahedra split into 6 tetrahedra each), the same layered
materials and load as config/demo.opts (clay above 40 m depth, sand to 140 m, rock below; one year of its
drawdown as the pore-pressure change of the clay and the sand), rollers on the sides and the bottom fixed,
P1 vector elements, the rigid-body modes as near-null space, and the KSP/PC options of pfault's solver file
(-pfault_solver NAME; of a fieldsplit file, the displacement split's, as pfault uses them without
faults). Prints the phases' wall times (mesh, stiffness assembly, solve) and the Krylov iterations as one
line and one JSON line, like box_assembly.py.
"""
import argparse
import json
import os
import sys
import time

import petsc4py

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
argv = sys.argv[1:]
extra = []
if "--" in argv:
    i = argv.index("--")
    argv, extra = argv[:i], argv[i + 1:]
p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--cells", type=int, default=55)
p.add_argument("--solver", default="gamg")
a = p.parse_args(argv)
petsc4py.init([sys.argv[0]] + extra)
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import numpy as np  # noqa: E402
import ufl  # noqa: E402
from dolfinx import fem, la, mesh  # noqa: E402
from dolfinx.fem.petsc import apply_lifting, assemble_matrix, assemble_vector, set_bc  # noqa: E402

sys.path.insert(0, ROOT)
from pfault.optionsfile import read_options_file  # noqa: E402
from pfault.solver.setup import find_solver_file  # noqa: E402

comm = MPI.COMM_WORLD
L, W, H = 2000.0, 2000.0, 200.0
LAYERS = ((160.0, 8e6, 10.0), (60.0, 12e6, 20.0))      # (z above which, E, drawdown over 10 years in m)
E_ROCK, NU, RHO_W, G = 1200e6, 0.30, 1000.0, 9.81

comm.Barrier()
t0 = time.perf_counter()
msh = mesh.create_box(comm, [np.array([0.0, 0.0, 0.0]), np.array([L, W, H])], [a.cells] * 3,
                      mesh.CellType.tetrahedron)
comm.Barrier()
t_mesh = time.perf_counter() - t0

V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
Q = fem.FunctionSpace(msh, ("DG", 0))
tdim = msh.topology.dim
ncells = msh.topology.index_map(tdim).size_local + msh.topology.index_map(tdim).num_ghosts
zc = mesh.compute_midpoints(msh, tdim, np.arange(ncells, dtype=np.int32))[:, 2]
E, dp = fem.Function(Q), fem.Function(Q)
E.x.array[:] = E_ROCK
dp.x.array[:] = 0.0
for z_top, e, drawdown in reversed(LAYERS):
    sel = zc > z_top
    E.x.array[sel] = e
    dp.x.array[sel] = -RHO_W * G * drawdown / 10.0          # one year of the ten-year ramp
mu = E / (2 * (1 + NU))
lam = E * NU / ((1 + NU) * (1 - 2 * NU))
u, v = ufl.TrialFunction(V), ufl.TestFunction(V)


def eps(w):
    return ufl.sym(ufl.grad(w))


def sigma(w):
    return 2 * mu * eps(w) + lam * ufl.tr(eps(w)) * ufl.Identity(3)


a_form = fem.form(ufl.inner(sigma(u), eps(v)) * ufl.dx)
L_form = fem.form(dp * ufl.div(v) * ufl.dx)        # -alpha dp I in the total stress, alpha = 1

fdim = tdim - 1
bcs = []
for axis, value in ((0, 0.0), (0, L), (1, 0.0), (1, W)):
    facets = mesh.locate_entities_boundary(msh, fdim, lambda x, ax=axis, val=value: np.isclose(x[ax], val))
    dofs = fem.locate_dofs_topological(V.sub(axis), fdim, facets)
    bcs.append(fem.dirichletbc(PETSc.ScalarType(0), dofs, V.sub(axis)))
bottom = mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[2], 0.0))
bcs.append(fem.dirichletbc(np.zeros(3, dtype=PETSc.ScalarType), fem.locate_dofs_topological(V, fdim, bottom), V))

comm.Barrier()
t0 = time.perf_counter()
A = assemble_matrix(a_form, bcs=bcs)
A.assemble()
comm.Barrier()
t_assembly = time.perf_counter() - t0
b = assemble_vector(L_form)
apply_lifting(b, [a_form], bcs=[bcs])
b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
set_bc(b, bcs)


def rigid_body_modes(V):
    """The six rigid-body modes (as in the DOLFINx elasticity demo), orthonormalised."""
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    ns = [la.create_petsc_vector(index_map, bs) for _ in range(6)]
    forms = [x.localForm() for x in ns]
    basis = [np.asarray(f.__enter__()) for f in forms]
    dofs = [V.sub(i).dofmap.list.array for i in range(3)]
    for i in range(3):
        basis[i][dofs[i]] = 1.0
    x = V.tabulate_dof_coordinates()
    blocks = V.dofmap.list.array
    x0, x1, x2 = x[blocks, 0], x[blocks, 1], x[blocks, 2]
    basis[3][dofs[0]], basis[3][dofs[1]] = -x1, x0
    basis[4][dofs[0]], basis[4][dofs[2]] = x2, -x0
    basis[5][dofs[2]], basis[5][dofs[1]] = x1, -x2
    for f in forms:
        f.__exit__(None, None, None)
    la.orthonormalize(ns)
    return PETSc.NullSpace().create(vectors=ns)


A.setNearNullSpace(rigid_body_modes(V))
opts = PETSc.Options()
solver_file = find_solver_file(a.solver)
entries = [(e.name, e.value) for e in read_options_file(solver_file)]
if ("pc_type", "fieldsplit") in entries:
    # pfault solves a scene without faults with the displacement split's options (configure_fieldsplit)
    split = "fieldsplit_displacement_"
    entries = [(k[len(split):], v) for k, v in entries if k.startswith(split)
               and not k.startswith((split + "ksp_", split + "mat_schur"))] + \
              [(k, v) for k, v in entries if not k.startswith(("pc_", "fieldsplit_"))]
for name, value in entries:
    if not opts.hasName("dx_" + name):
        opts.setValue("dx_" + name, "" if value is None else value)
for i in range(0, len(extra) - 1, 2):
    if extra[i].startswith("-") and not extra[i].startswith("-dx_"):
        opts.setValue("dx_" + extra[i][1:], extra[i + 1])
ksp = PETSc.KSP().create(comm)
ksp.setOptionsPrefix("dx_")
ksp.setOperators(A)
ksp.setFromOptions()
x = A.createVecRight()
comm.Barrier()
t0 = time.perf_counter()
ksp.solve(b, x)
comm.Barrier()
t_solve = time.perf_counter() - t0
fig = {"ranks": comm.size, "cells": msh.topology.index_map(tdim).size_global, "dofs": A.getSize()[0],
       "mesh_s": t_mesh, "assembly_s": t_assembly, "solve_s": t_solve, "ksp_its": ksp.getIterationNumber(),
       "reason": int(ksp.getConvergedReason()), "max_subsidence_m": float(-x.min()[1])}
PETSc.Sys.Print(f"DOLFINx box: {fig['cells']} tets, {fig['dofs']} dofs on {fig['ranks']} ranks: mesh "
                f"{t_mesh:.2f} s, stiffness assembly {t_assembly:.2f} s, solve {t_solve:.2f} s "
                f"({fig['ksp_its']} Krylov its, reason {fig['reason']})")
PETSc.Sys.Print(json.dumps(fig))
