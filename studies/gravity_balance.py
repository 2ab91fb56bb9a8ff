#!/usr/bin/env python
"""The balance of the vertex forces of a geostatic start's glued gravity state, from the cell stresses of its P1
part alone and with the face bubbles' strain (what the initial stress is built from).

    .venv/bin/python studies/gravity_balance.py config/wuxi.opts [-pfault_mesh_size_factor 3 ...]

Builds the scene in-process (one rank), solves the glued gravity state as the geostatic start does and prints, over
the free displacement dofs off the fault, the largest |sum over the cells of V sigma . grad(l_a) - f_a| (f the P1
gravity load) relative to the sum of the magnitudes of the cells' terms: zero to round-off for cell stresses in
equilibrium.
"""
import sys

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


petsc4py.init([sys.argv[0], *petsc_arguments(sys.argv[1], []), "-pfault_figures", "false"] + sys.argv[2:])
import numpy as np  # noqa: E402

from pfault.physics import elasticity as el  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402
from pfault.solver.equations import constrained_local  # noqa: E402


def main() -> None:
    sim = Simulation(sys.argv[1], sys.argv)
    eq = sim.model.equations
    asm, dofmap = eq.asm, eq.dofmap
    eq.loads.gravity(eq.loads.f)
    ug = sim.state.u.duplicate()
    sim.solver.solve_linear(eq.initial_operator(), eq.loads.f, ug)
    u = eq.local_array(ug)
    ug.destroy()
    grav = np.zeros(dofmap.n_local)
    asm.gravity_load(sim.settings.gravity, grav)
    ok = ~constrained_local(eq.mesh, dofmap)
    split = dofmap.vert_sides > 1
    for side in (0, 1):
        ok[dofmap.vertex_dofs(side)[split].ravel()] = False
    ok[sim.model.faces.lm_dofs.ravel()] = False
    for name, sig in (("P1 part", asm.effective_stress(u)),
                      ("with the bubbles", eq.effective_stress(u, sim.state.histories))):
        fe = el.stress_divergence_force(asm.grad, asm.vol, sig)
        r, mag = np.zeros(dofmap.n_local), np.zeros(dofmap.n_local)
        asm.scatter_cell_forces(fe, r)
        asm.scatter_cell_forces(np.abs(fe), mag)
        res = np.abs(r - grav)[ok] / np.maximum(mag[ok], 1e-300)
        print(f"{name}: largest relative imbalance of the vertex forces {res.max():.3g}")
    sim.destroy()


if __name__ == "__main__":
    main()
