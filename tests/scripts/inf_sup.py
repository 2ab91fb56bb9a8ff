#!/usr/bin/env python
"""Inf-sup stability of the P0 tractions against the P1 displacements enriched by the face bubbles.

Two blocks across a full fault plane, all faces stuck. The constraint rows of stuck faces are -c (A g) with A g the
face-mean jump times the area, P1 part and bubble part; in those units the condensed saddle point is
[K_c B_c^T; B_c -D] (K_c, B_c: the condensed stiffness and constraint, D = C K_bb^-1 C^T the bubbles' multiplier
block), and the multiplier Schur complement of the uncondensed system is B_c K_c^-1 B_c^T + D. Without the
bubbles (B K^-1 B^T) it has a null space: P0 tractions on triangles outnumber the P1 jumps, the spurious traction
modes. The discrete inf-sup constant of the pair in the energy norm of the displacement and the h-weighted L2
norm of the traction (the mesh-independent stand-in for H^-1/2), beta^2 = E lambda_min(S, diag(A h)), is
printed with the count of null modes of each. Prints JSON. ``-pfault_box_cells`` chooses the mesh.
"""
import json
import sys

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


petsc4py.init([sys.argv[0], *petsc_arguments("config/two_blocks.opts", []), "-pfault_output_dir", "/tmp/pfault-infsup",
               "-pfault_bc_xmax_displacement", "0,0,0.2", "-pfault_bc_xmax_components", "x,z"] + sys.argv[1:])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402

sim = Simulation("config/two_blocks.opts", sys.argv)
p, f = sim.model.equations, sim.model.equations.terms[0]
sim.state.histories = p.begin_step(sim.state.u, sim.state.histories)
p.assemble_jacobian(sim.state.u, p.J, sim.state.histories)
J = p.J.convert("dense").getDenseArray().copy()
loc = np.zeros(sim.model.dofmap.n_local)
loc[f.faces.lm_dofs.ravel()] = 1.0
mark = p.to_global(loc, PETSc.InsertMode.INSERT_VALUES).getArray() > 0.5
# the constraint rows of stuck faces are -c (A g): divide each row by its -c
loc[f.faces.lm_dofs] = -np.column_stack([f.laws.lagrange.c_n, f.laws.lagrange.c_t, f.laws.lagrange.c_t])
rowscale = p.to_global(loc, PETSc.InsertMode.INSERT_VALUES).getArray()
J[mark] /= rowscale[mark, None]
bc = np.zeros(len(mark), bool)
bc[p.bc_rows] = True
lm = np.nonzero(mark)[0]
u = np.nonzero(~mark & ~bc)[0]
K = J[np.ix_(u, u)]
B = J[np.ix_(lm, u)]
D = -J[np.ix_(lm, lm)]
schur = B @ np.linalg.solve(K, B.T)
schur = 0.5 * (schur + schur.T)
full = 0.5 * (schur + D + (schur + D).T)
# B without the bubbles' part: the P1 jump of the vertices (A/3 sign R per vertex), from the faces' dofs
B1 = np.zeros_like(B)
gidx = {int(g): i for i, g in enumerate(u)}
lm_of = {int(g): i for i, g in enumerate(lm)}
sign = f.faces.dofs.sign.reshape(6, 3)[:, 0]
for k in range(f.faces.nf):
    rows = [lm_of[int(g)] for g in f.faces.dofs.g_lm[k]]
    for v in range(6):
        for c in range(3):
            g = int(f.faces.dofs.g_u[k, 3 * v + c])
            if g in gidx:
                B1[rows, gidx[g]] += sign[v] * f.faces.area[k] / 3.0 * f.faces.R[k][:, c]
K1 = K.copy()       # (K_c is the condensed stiffness; the P1 pair's own K differs only in the enriched cells)
p1 = B1 @ np.linalg.solve(K1, B1.T)
weight = np.repeat(f.faces.area * f.faces.h, 3)     # serial face order is the multipliers' order on one rank
young = float(np.mean(f.faces.young))
iw = 1.0 / np.sqrt(weight)
ev_full = np.linalg.eigvalsh(iw[:, None] * full * iw[None, :])      # S v = lambda diag(weight) v
ev_p1 = np.linalg.eigvalsh(iw[:, None] * 0.5 * (p1 + p1.T) * iw[None, :])
out = {"multipliers": int(len(lm)), "faces": int(f.faces.nf), "h": float(np.sqrt(np.mean(f.faces.area))),
       "jump_dofs": int(np.linalg.matrix_rank(B1)),
       "null_modes_p1": int(np.sum(ev_p1 < 1e-10 * ev_p1.max())),
       "null_modes": int(np.sum(ev_full < 1e-10 * ev_full.max())),
       "beta": float(np.sqrt(young * ev_full.min())), "beta_max": float(np.sqrt(young * ev_full.max())),
       "D_over_schur": float(np.abs(D).max() / np.abs(schur).max())}
sim.destroy()
print(json.dumps(out))
