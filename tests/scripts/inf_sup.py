#!/usr/bin/env python
"""Spurious traction modes of the P1-P0 saddle point and their removal by the stabilisation.

Two blocks across a full fault plane, all faces stick. With K the displacement block and B the stick
constraint rows, the multiplier Schur complement B K^-1 B^T is singular: P0 tractions on triangles
outnumber the P1 jumps. Its null vectors are the spurious (oscillating) traction modes. The stabilisation
block S makes B K^-1 B^T + S positive definite. Prints JSON.
"""
import json
import sys

import petsc4py

petsc4py.init([sys.argv[0], "-options_file", "config/two_blocks.opts", "-pfault_output_dir", "/tmp/pfault-infsup",
               "-pfault_box_cells", "4,3,3", "-pfault_bc_xmax_displacement", "0,0,0.2",
               "-pfault_bc_xmax_components", "x,z"] + sys.argv[1:])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402

sim = Simulation("config/two_blocks.opts", sys.argv)
p, f = sim.model.equations, sim.model.faults
f.begin_step(p.local_array(sim.state.u))
p.assemble_jacobian(sim.state.u, p.J)
J = p.J.convert("dense").getDenseArray().copy()
loc = np.zeros(sim.model.dofmap.n_local)
loc[f.faces.lm_dofs.ravel()] = 1.0
mark = p.to_global(loc, PETSc.InsertMode.INSERT_VALUES).getArray() > 0.5
# the constraint rows of stuck faces are -c (A g + S dt) (forces); in jump units A g + S dt the saddle point is
# symmetric, [K B^T; B -S]: divide each row by its -c
loc[f.faces.lm_dofs] = -np.column_stack([f.law.c_n, f.law.c_t, f.law.c_t])
rowscale = p.to_global(loc, PETSc.InsertMode.INSERT_VALUES).getArray()
J[mark] /= rowscale[mark, None]
bc = np.zeros(len(mark), bool)
bc[p.bc_rows] = True
lm = np.nonzero(mark)[0]
u = np.nonzero(~mark & ~bc)[0]
K = J[np.ix_(u, u)]
B = J[np.ix_(lm, u)]
S = -J[np.ix_(lm, lm)]
schur = B @ np.linalg.solve(K, B.T)
ev = np.linalg.eigvalsh(0.5 * (schur + schur.T))
tol = 1e-10 * ev.max()
n_null = int(np.sum(ev < tol))
w, V = np.linalg.eigh(0.5 * (schur + schur.T))
# the spurious modes carry no net force: their area-weighted mean per component vanishes (they oscillate)
modes = V[:, :n_null].T.reshape(n_null, -1, 3)
area = f.faces.area[None, :, None]
mean = np.abs((modes * area).sum(axis=1)) / area.sum()
rms = np.sqrt((modes ** 2 * area).sum(axis=1) / area.sum())
net = float(np.max(mean / np.maximum(rms, 1e-300)))
stab = 0.5 * (schur + S + (schur + S).T)
ev_s = np.linalg.eigvalsh(stab)
out = {"multipliers": int(len(lm)), "jump_dofs": int(np.linalg.matrix_rank(B)), "null_modes": n_null,
       "mode_net_over_rms": net, "min_eig_stabilized_rel": float(ev_s.min() / ev_s.max()),
       "S_over_schur": float(np.abs(S).max() / np.abs(schur).max())}
sim.destroy()
print(json.dumps(out))
