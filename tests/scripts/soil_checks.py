#!/usr/bin/env python
"""The law with memory in the finite-element equations (pfault.soils.term), in-process on small scenes; prints one
JSON line.

    mpirun -n 2 python tests/scripts/soil_checks.py [column] [taylor]

``column``: config/soil_column.opts (a laterally confined column of 40 two-metre cell layers: a linear crust over a
clay overconsolidated 1.3 times, a normally consolidated sand and a clay preconsolidated 3 m of head below the
initial heads) started from the layered initial stress of its cells' layers, uniform in each layer of cells (the
vertical effective stress of the column's weight at the layer's mid-depth, K0 = nu/(1-nu)): P1's constant-strain
cells then hold the 1-D solution exactly, and the settlement of the land surface after each drawdown stage is the
closed-form integral of the index law over those layers (studies/soil_column.py, each layer of cells one layer of
uniform initial stress) and CSUB's no-delay relation with the equivalent storage values, at one step and at four
steps per stage; then the same column with CSUB's head-based skeletal storages (Sske, Sskv) against CSUB's
HEAD_BASED relation. ``taylor``: the Taylor test of the term's Jacobian on a 3 x 3 x 4 box of a normally consolidated
and an overconsolidated clay after a first drawdown step: from the converged state u_n along a random strain
increment (cells compacting on the virgin line, cells on their swelling line being unloaded or reloaded below
their cap, cells crossing their cap within the step), and at u_n itself, where the normally consolidated cells sit
on their cap (the switch): unloaded along -du with the Jacobian the residual's branches give (elastic), loaded along
+du with the virgin branch's (configuration VIRGIN).
"""
import json
import sys

import petsc4py

CASES = [a for a in sys.argv[1:] if not a.startswith("-")] or ["column", "taylor"]
petsc4py.init([sys.argv[0]])
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.initial import GeostaticStart  # noqa: E402
from pfault.physics import soil as sl  # noqa: E402
from pfault.run import relative_displacement, surface_figures  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402
from studies import soil_column as sc  # noqa: E402

COMM = PETSc.COMM_WORLD
G = 9.80665
GAMMA_W = 1000.0 * G
COLUMN = "config/soil_column.opts"
CLAYS = np.array([4.0, 10.0, 3.0, 14.0, 8.0])        # the scene's stages (m of drawdown; the sand twice)
LAYERS = {"clay1": (2.0, 20.0), "sand": (20.0, 50.0), "clay2": (50.0, 80.0)}
ALPHA = {"clay1": 1.0, "sand": 1.0, "clay2": 0.95}
STORAGE = {"clay1": (3e-5, 6e-4), "sand": (5e-6, 2e-5), "clay2": (2e-5, 4e-4)}   # Sske, Sskv (1/m)


def simulation(scene: str, options: dict):
    """The Simulation of ``scene`` with ``options`` on top (a value None removes the scene's option), from an options
    database that holds nothing else."""
    opts = PETSc.Options()
    for key in opts.getAll():
        opts.delValue(key)
    if scene:
        opts.insertString(f"-options_file {scene}")
    for key, value in options.items():
        if value is None:
            opts.delValue(key)
        else:
            opts.setValue(key, value)
    return Simulation(scene, [])


def effective(depth: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Vertical effective stress (Pa, compression positive) of the column at ``depth``: a 2 m dry crust of 1,700
    kg/m^3 over saturated layers of 2,000 kg/m^3, the water table 2 m deep."""
    total = G * (1700.0 * np.minimum(depth, 2.0) + 2000.0 * np.maximum(depth - 2.0, 0.0))
    return total - alpha * GAMMA_W * np.maximum(depth - 2.0, 0.0)


def layered_start(sim) -> list:
    """Start ``sim`` (the column) from its layered initial stress (uniform in each layer of cells); returns the
    closed form's layers, one per layer of soil cells."""
    eq, m = sim.model.equations, sim.model
    z = m.assembler.centroids[:, 2]
    h = 80.0 / 40
    mid = (np.floor(-z / h) + 0.5) * h                          # the cell layer's mid-depth
    names = m.scene.material_names
    alpha = m.assembler.alpha
    sv = effective(mid, alpha)
    nu = m.properties.poisson_ratio
    p0 = GAMMA_W * np.maximum(m.settings.water_table - z, 0.0)
    sigma0 = np.zeros((len(z), 3, 3))
    sigma0[:, 0, 0] = sigma0[:, 1, 1] = -(nu / (1 - nu)) * sv - alpha * p0
    sigma0[:, 2, 2] = -sv - alpha * p0
    GeostaticStart(eq, m.settings).start(sim.state, sigma0)
    layers = []
    for name, (top, bottom) in LAYERS.items():
        k = names.index(name)
        soil = m.scene.soils[k]
        for d in np.arange(top + h / 2, bottom, h):
            s0 = float(effective(np.array(d), ALPHA[name]))
            kw = ({"cc": soil.compression, "cr": soil.recompression, "e0": soil.void_ratio} if soil.form == "index"
                  else {"sskv": soil.compression, "sske": soil.recompression})
            layers.append(sc.Layer(d - h / 2, h, s0, 0.0, alpha=ALPHA[name], precon=soil.preconsolidation,
                                   precon_value=soil.preconsolidation_value or 0.0, **kw))
    return layers


def run_steps(sim) -> list:
    """The time loop without observers: the land surface's largest subsidence after every step."""
    m, out = sim.model, []
    for t_prev, t in zip(sim.times[:-1], sim.times[1:]):
        m.source.advance_to(t)
        solve = sim.stepper.solve(float(t_prev), float(t))
        if not solve.converged:
            raise RuntimeError(f"step to t = {t} did not converge")
        out.append(surface_figures(m, relative_displacement(m, sim.state))[0])
    return out


def column(results: dict) -> None:
    dd = np.column_stack([CLAYS, 2 * CLAYS, CLAYS])
    for form in ("index", "storage"):
        extra = {}
        if form == "storage":
            for name, (sske, sskv) in STORAGE.items():
                p = f"pfault_material_{name}_"
                extra.update({p + "compression_index": None, p + "recompression_index": None, p + "void_ratio": None,
                              p + "elastic_skeletal_specific_storage": repr(sske),
                              p + "inelastic_skeletal_specific_storage": repr(sskv)})
        for per_stage in (1, 4):
            sim = simulation(COLUMN, {"pfault_time_steps": str(5 * per_stage), **extra})
            layers = layered_start(sim)
            fe = np.array(run_steps(sim))[per_stage - 1::per_stage]
            stage_dd = np.repeat(dd, [sum(1 for ly in layers if LAYERS[n][0] <= ly.top < LAYERS[n][1])
                                      for n in LAYERS], axis=1)
            exact = sc.settlement(layers, stage_dd)
            csub = sc.csub_settlement(layers, stage_dd, "equivalent" if form == "index" else "head")
            results[f"column_{form}_{per_stage}"] = {"fe": fe.tolist(), "closed_form": exact.tolist(),
                                                     "csub": csub.tolist(),
                                                     "fe_closed_form": float(np.abs(fe / exact - 1).max()),
                                                     "csub_closed_form": float(np.abs(csub / exact - 1).max()),
                                                     "fe_csub": float(np.abs(fe / csub - 1).max())}
            sim.destroy()


TAYLOR_BOX = {"pfault_box_size": "30,30,40", "pfault_box_cells": "3,3,4", "pfault_box_materials": "nc,oc",
              "pfault_box_interfaces": "20", "pfault_time_steps": "1", "pfault_time_end": "1",
              **{f"pfault_material_{m}_{k}": v for m in ("nc", "oc") for k, v in (
                  ("compression_index", "0.3"), ("recompression_index", "0.05"), ("void_ratio", "0.9"),
                  ("poisson_ratio", "0.3"), ("density", "2000"), ("head_drawdown", "0:0,1:6"))},
              "pfault_material_oc_overconsolidation_ratio": "1.25", "pfault_water_table": "0",
              "pfault_geostatic": "true", "pfault_solver": "mumps", "pfault_output_dir": "/tmp/soil_checks",
              **{f"pfault_bc_{b}_type": "roller" for b in ("xmin", "xmax", "ymin", "ymax")},
              "pfault_bc_bottom_type": "fixed"}
H = (1e-2, 1e-3, 1e-4)


def taylor_errors(sim, x, v, config=None) -> dict:
    """|F(x + h v) - F(x) - h J v| for h in H (J with the terms' configurations ``config``, else x's), its orders,
    and how many cells are off the branch of J at some x + h v."""
    eq, hist = sim.model.equations, sim.state.histories
    F0, Fh, Jv, xh = x.duplicate(), x.duplicate(), x.duplicate(), x.duplicate()
    eq.residual(x, F0, hist)
    eq.assemble_jacobian(x, eq.J, hist, config)
    eq.J.mult(v, Jv)
    branch0 = eq.configuration(x, hist)[0] if config is None else config[0]
    e2, off = [], 0
    for h in H:
        x.copy(xh)
        xh.axpy(h, v)
        eq.residual(xh, Fh, hist)
        Fh.axpy(-1.0, F0)
        Fh.axpy(-h, Jv)
        e2.append(Fh.norm())
        off = max(off, int(np.count_nonzero(eq.configuration(xh, hist)[0] != branch0)))
    for vec in (F0, Fh, Jv, xh):
        vec.destroy()
    return {"e2": e2, "order2": [float(np.log10(a / b)) for a, b in zip(e2, e2[1:])],
            "cells_off_branch": int(COMM.tompi4py().allreduce(off))}


def taylor(results: dict) -> None:
    sim = simulation("", TAYLOR_BOX)
    sim._initial_state()
    eq, m, state = sim.model.equations, sim.model, sim.state
    run_steps(sim)                                        # u_n: the first drawdown step, converged and committed
    term = eq.terms[0]
    h0 = state.histories[0]
    on_cap = np.isclose(h0.law.preconsolidation, sl.mean_stress(h0.law.stress), rtol=1e-12, atol=0.0)
    rng = np.random.default_rng(7 + COMM.rank)
    du = state.u.copy()                                   # the step's increment (u_ref = 0 displacements)
    du.axpy(-1.0, state.u_ref)
    rstart, rend = du.getOwnershipRange()
    bc = eq.bc_rows - rstart
    x, v = state.u.copy(), state.u.duplicate()
    scale = du.norm(PETSc.NormType.INFINITY)
    # x: u_n plus a random field half the step's size; v: random, zero on Dirichlet rows
    noise = rng.normal(size=rend - rstart) * 0.5 * scale
    noise[bc] = 0.0
    x.setArray(x.getArray() + noise)
    va = rng.normal(size=rend - rstart) * 0.1 * scale
    va[bc] = 0.0
    v.setArray(va)
    branch = eq.configuration(x, state.histories)[0]
    kinds = {"virgin_from_cap": on_cap & (branch == sl.VIRGIN), "unloading_from_cap": on_cap & (branch == sl.ELASTIC),
             "below_cap_elastic": ~on_cap & (branch == sl.ELASTIC), "crossing_cap": ~on_cap & (branch == sl.VIRGIN)}
    counts = {k: int(COMM.tompi4py().allreduce(int(np.count_nonzero(w)))) for k, w in kinds.items()}
    results["taylor_mixed"] = {**taylor_errors(sim, x, v), "cells": counts}
    # at the switch: u_n itself, the normally consolidated cells on their cap
    virgin = np.where(on_cap, sl.VIRGIN, sl.ELASTIC)
    du.scale(-1.0)
    results["taylor_switch_unloading"] = taylor_errors(sim, state.u, du)
    du.scale(-1.0)
    results["taylor_switch_loading_elastic"] = taylor_errors(sim, state.u, du)
    results["taylor_switch_loading_virgin"] = taylor_errors(sim, state.u, du, config=(virgin,))
    results["taylor_switch_cells_on_cap"] = int(COMM.tompi4py().allreduce(int(np.count_nonzero(on_cap))))
    for vec in (x, v, du):
        vec.destroy()
    sim.destroy()


def main() -> None:
    results = {"ranks": COMM.size}
    if "column" in CASES:
        column(results)
    if "taylor" in CASES:
        taylor(results)
    if COMM.rank == 0:
        print(json.dumps(results))


if __name__ == "__main__":
    main()
