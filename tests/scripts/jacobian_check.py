#!/usr/bin/env python
"""Taylor test of the full fault system F(x) (elasticity + interface terms) against its Jacobian J(x).

    mpirun -n 2 python tests/scripts/jacobian_check.py [-pfault_box_cells 4,4,4 ...]

Sets up the two-blocks scene in-process (Lagrange multipliers, then penalty), places the state x in a chosen
contact configuration and measures, for h = 1e-2, 1e-3, 1e-4 and a direction v that vanishes on Dirichlet rows,

    e1(h) = ||F(x + h v) - F(x)||          (first order: ~ h)
    e2(h) = ||F(x + h v) - F(x) - h J v||  (Taylor remainder: ~ h^2 where F is nonlinear, round-off where affine)

Cases: Lagrange faces in the stick, slip (with a slip increment, and before any increment), open branches of the
semismooth law and a mix of the three (face id mod 3), placed there by the multipliers and jumps of x; penalty
faces in the stick, slip and open branches of the return map (selected by the jump). The branch of every face is
checked not to change between x and x + h v (the test stays away from the kinks). Then every case again with
cohesion (prefix ``cohesive_``: the tension cut-off at c / tan(phi) on open faces). Then a candidate surface
(pfault.faults.breaking) under the mixed case's multipliers: every face intact (``intact_mixed``: held stuck
whatever its traction), and the faces of even serial id broken with a residual cohesion (``broken_mixed``: intact
faces stuck beside broken ones stuck, slipping and open). Prints one JSON line
{case: {e1, e2, order1, order2, states, ...}}.
"""
import json
from dataclasses import replace
import sys

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


SCENE = "config/two_blocks.opts"
# --junction: the Lagrange cases on two faults crossing (an X junction: 4 pieces at each junction vertex, the
# offset on piece 1 of every split vertex) in place of the two blocks
JUNCTION = "--junction" in sys.argv
if JUNCTION:
    sys.argv.remove("--junction")
    SCENE = "config/hard/two_faults.opts"
    sys.argv += ["-pfault_box_fault_planes", "fa:x:175:0:200:-40:0,fb:y:175:0:200:-40:0"]
petsc4py.init([sys.argv[0], *petsc_arguments(SCENE, [])] + sys.argv[1:])
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.faults import contact as ct  # noqa: E402
from pfault.faults.history import StepStart  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402

H = (1e-2, 1e-3, 1e-4)
COHESION = 1e5      # Pa: the cohesive cases' c (tensile strength c / tan(30 degrees) = 1.7e5 Pa)
COMM = PETSc.COMM_WORLD


def make_vectors(sim, offset, rng, u_noise=1e-4, t_mean=(-1e6, 2e5, -1e5), t_noise=1e5):
    """x: small random displacement + a uniform jump `offset` (global) of the plus side of the fault, random
    multipliers around t_mean (one row, or one row per owned face); v: random, zero on Dirichlet rows."""
    p, f, dm = sim.model.equations, sim.model.equations.terms[0], sim.model.dofmap
    x = sim.state.u.duplicate()
    v = sim.state.u.duplicate()
    rstart, rend = x.getOwnershipRange()
    n = rend - rstart
    lm = (f.faces.dofs.g_lm.ravel() - rstart) if f.faces.nf else np.zeros(0, np.int64)
    xa = rng.normal(size=n) * u_noise
    tm = np.asarray(t_mean).reshape(-1, 3)[np.arange(f.faces.nf) if np.ndim(t_mean) > 1 else 0]
    xa[lm] = (tm + t_noise * rng.normal(size=(len(lm) // 3, 3))).ravel()
    x.setArray(xa)
    # plus-side dofs of every split vertex (owned or ghost, the same value on every rank): add the offset
    loc = p.local_array(x)
    split = dm.vert_sides > 1
    plus = dm.vertex_dofs(1)[split]
    loc[plus] += np.asarray(offset)[None, :]
    p.to_global(loc, PETSc.InsertMode.INSERT_VALUES, out=x)
    va = rng.normal(size=n) * 1e-3
    va[lm] = rng.normal(size=len(lm)) * 1e5
    va[p.bc_rows - rstart] = 0.0
    v.setArray(va)
    return x, v


def taylor(sim, x, v):
    p, hist = sim.model.equations, sim.state.histories
    F0, Fh, Jv, xh = x.duplicate(), x.duplicate(), x.duplicate(), x.duplicate()
    p.residual(x, F0, hist)
    p.assemble_jacobian(x, p.J, hist)
    p.J.mult(v, Jv)
    states0 = p.configuration(x, hist)[0]
    e1, e2, same = [], [], True
    for h in H:
        x.copy(xh)
        xh.axpy(h, v)
        p.residual(xh, Fh, hist)
        Fh.axpy(-1.0, F0)
        e1.append(Fh.norm())
        Fh.axpy(-h, Jv)
        e2.append(Fh.norm())
        same &= bool(np.array_equal(p.configuration(xh, hist)[0], states0))
    same = bool(COMM.tompi4py().allreduce(same, op=MPI.LAND))
    counts = np.bincount(states0, minlength=3) if len(states0) else np.zeros(3, np.int64)
    counts = COMM.tompi4py().allreduce(counts)
    out = {"h": list(H), "e1": e1, "e2": e2, "F_norm": F0.norm(), "Jv_norm": Jv.norm(),
           "order1": [float(np.log10(a / b)) for a, b in zip(e1, e1[1:])],
           "order2": [float(np.log10(a / b)) for a, b in zip(e2, e2[1:])],
           "remainder_ratio": [float(b / a) for a, b in zip(e1, e2)],
           "states": {name: int(c) for name, c in zip(ct.STATE_NAMES, counts)}, "states_unchanged": same}
    for vec in (F0, Fh, Jv, xh):
        vec.destroy()
    return out


def set_history(sim, rng, g_prev, t_prev):
    """Start-of-step jump (local frame) of the owned faces (``t_prev``: the start's tractions, which the laws do not
    read, drawn to keep the random sequence)."""
    f = sim.model.equations.terms[0]
    g = np.asarray(g_prev)[None, :] + 1e-4 * rng.normal(size=(f.faces.nf, 3))
    np.asarray(t_prev)[None, :] + 1e4 * rng.normal(size=(f.faces.nf, 3))
    h = sim.state.histories[0]
    sim.state.histories = (replace(h, start=StepStart(g, np.zeros(f.faces.nf, np.int64))),)


# multipliers (local frame = global here: n = +x) and plus-side jumps that put a face in each branch: stuck
# (compressed, shear inside the cone, no slip increment), slipping with an increment, slipping before any
# increment (shear beyond the cone), open (an opening jump)
T_STICK, T_SLIP, T_OPEN = (-1e6, 1e5, 5e4), (-1e6, 6e5, -5e5), (-1e5, 1e5, 0.0)
G_PREV = (0.0, 1e-3, 2e-3)


def lagrange_cases(results, prefix=""):
    sim = Simulation(SCENE, sys.argv)
    p, f = sim.model.equations, sim.model.equations.terms[0]
    p.loads.set(1.0)
    rng = np.random.default_rng(1234 + COMM.rank)
    counts = COMM.tompi4py().allgather(f.faces.nf)
    results["faces_per_rank"] = [int(c) for c in counts]
    # the mixed case: one common jump (no opening, the start's slip) and the branch set by the multiplier alone
    # (open: tensile), by serial face id: the same configuration at any rank count
    mixed_t = np.array([T_STICK, T_SLIP, (5e6, 1e5, 0.0)])[f.faces.face % 3]
    for name, t_mean, offset in (("stick", T_STICK, (0.0, 1e-3, 2e-3)), ("slip", T_SLIP, (0.0, 2e-2, -2e-2)),
                                 ("open", T_OPEN, (2e-1, 0.0, 0.0)), ("slip_start", T_SLIP, (0.0, 1e-3, 2e-3)),
                                 ("mixed", mixed_t, None)):
        set_history(sim, rng, g_prev=G_PREV, t_prev=(-9e5, 1e4, 5e4))
        x, v = make_vectors(sim, offset=(0.0, 1e-3, 2e-3) if offset is None else offset, rng=rng, t_mean=t_mean,
                            t_noise=2e4)
        results[prefix + "lagrange_" + name] = taylor(sim, x, v)
        x.destroy()
        v.destroy()
    sim.destroy()


def breaking_cases(results):
    """The mixed case's multipliers on a candidate surface: every face intact, then half of them broken."""
    opts = PETSc.Options()
    for key, value in (("tensile_strength", 5e4), ("residual_cohesion", 3e4)):
        opts.setValue(f"pfault_fault_fault_{key}", value)
    sim = Simulation(SCENE, sys.argv)
    f = sim.model.equations.terms[0]
    sim.model.equations.loads.set(1.0)
    rng = np.random.default_rng(2468 + COMM.rank)
    mixed_t = np.array([T_STICK, T_SLIP, (5e6, 1e5, 0.0)])[f.faces.face % 3]
    for name, broken in (("intact_mixed", np.zeros(f.faces.nf, bool)), ("broken_mixed", f.faces.face % 2 == 0)):
        sim.state.histories = (sim.state.histories[0].with_breaks(broken, 0.0),)
        set_history(sim, rng, g_prev=G_PREV, t_prev=(-9e5, 1e4, 5e4))
        x, v = make_vectors(sim, offset=(0.0, 1e-3, 2e-3), rng=rng, t_mean=mixed_t, t_noise=2e4)
        results[name] = taylor(sim, x, v)
        x.destroy()
        v.destroy()
    sim.destroy()
    for key in ("tensile_strength", "residual_cohesion"):
        opts.delValue(f"pfault_fault_fault_{key}")


def penalty_cases(results, prefix=""):
    opts = PETSc.Options()
    opts.setValue("pfault_fault_fault_method", "penalty")
    sim = Simulation(SCENE, sys.argv)
    p, f = sim.model.equations, sim.model.equations.terms[0]
    p.loads.set(1.0)
    rng = np.random.default_rng(4321 + COMM.rank)
    k = float(np.mean(f.laws.penalty.c_n)) if f.faces.nf else 0.0
    results["penalty_stiffness"] = COMM.tompi4py().allgather(k)
    # t_N = k g_N, tau_L = tan(phi) |t_N|; trial shear = t_T^n + k (g_T - g_T^n)
    for name, offset, g_prev, t_prev in (
            ("stick", (-2e-2, 0.0, 1e-3), (0.0, 0.0, 0.0), (-5e5, 0.0, 1e4)),
            ("slip", (-1e-2, 0.0, 8e-2), (0.0, 1e-3, 2e-3), (-5e5, 1e4, 5e4)),
            ("open", (1e-2, 0.0, 3e-2), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))):
        set_history(sim, rng, g_prev, t_prev)
        # (a penalty face's multipliers are its traction; small ones keep the bubbles' part of the jump small, so
        # that the jump alone selects the branch)
        x, v = make_vectors(sim, offset=offset, rng=rng, t_mean=(0.0, 0.0, 0.0), t_noise=1e3)
        results[prefix + "penalty_" + name] = taylor(sim, x, v)
        x.destroy()
        v.destroy()
    sim.destroy()
    opts.delValue("pfault_fault_fault_method")


if __name__ == "__main__" and JUNCTION:
    res = {"ranks": COMM.size}
    lagrange_cases(res)
    if COMM.rank == 0:
        print(json.dumps(res))
elif __name__ == "__main__":
    res = {"ranks": COMM.size}
    lagrange_cases(res)
    penalty_cases(res)
    # the same with cohesion: open faces then carry the tensile strength c / tan(phi)
    PETSc.Options().setValue("pfault_fault_fault_cohesion", COHESION)
    lagrange_cases(res, "cohesive_")
    penalty_cases(res, "cohesive_")
    breaking_cases(res)
    if COMM.rank == 0:
        print(json.dumps(res))
