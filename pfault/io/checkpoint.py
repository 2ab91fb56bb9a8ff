"""The state after the last completed step (``checkpoint.h5``), from which ``-pfault_restart DIR`` continues.

Written after every completed step, whole, into ``checkpoint.h5.tmp`` and then renamed over the old one: a
checkpoint is either the previous one or the new one, never half of each.

Vectors are stored by mesh point in the serial numbering, so a checkpoint does not depend on the partition
(a run on 2 ranks may continue on 1 or 3): per serial vertex its displacement dofs (6 columns: side 0, then
the plus side of a split fault vertex, zero elsewhere) and, for the serial cells that carry fault multipliers
(``cell_ids``), their multipliers (3 per fault face the cell owns, zero-padded to the widest cell).

What a run carries from one step to the next (pfault.solver.problem.Problem, pfault.faults.interface,
pfault.solver.flow): the solution u, the initial state u_ref, the initial stress sigma0, each fault face's
initial traction ``t0`` and the pore pressure alpha p its contact law saw in the step (``pn``, which the next
step's ``begin_step`` measures the faces' start state under), and the flow model's head, time and records. The
faces' stick/slip/open states are not state: the semismooth law reads them from u. The Jacobian and its
factorisation are rebuilt at the first solve from the same values.

Contents (datasets; attributes on the root)
- ``u/vertex``, ``u/cell_ids``, ``u/cell``: the solution (displacements and fault multipliers) at the step's
  time
- ``u_ref/...``: the state at t = 0 (after the geostatic initial state)
- ``u_previous/...``, attribute ``previous_time``: the state converged before u (a fault scene's predictor
  extrapolates from it), when there is one
- ``sigma0`` (cells x 9, Pa): the geostatic initial stress, when there is one
- ``faults/t0`` (serial fault faces x 3, Pa, local frame), ``faults/pn`` (serial fault faces, Pa)
- ``flow/head`` (serial vertices, m), ``flow/history`` (its step records, JSON as bytes), attribute
  ``flow_time``
- attributes ``format``, ``step``, ``time_s``, ``scene``, ``ranks``, ``nodes``, ``cells``, ``fault_faces``,
  ``dofs``, ``fields``, ``geostatic``, ``flow``
"""

from __future__ import annotations

import json
import os

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..errors import InputError
from ..mesh import distributed
from . import run_options
from .output import TMP_SUFFIX, open_h5

FORMAT = 2                     # 1: the active-set solver's (fault states, predictor)
NAME = "checkpoint.h5"
CELL_COLUMNS = 12              # up to 4 fault faces per cell, 3 multipliers each


# ------------------------------------------------------------------------------------------------------
# vectors by mesh point
# ------------------------------------------------------------------------------------------------------
def point_dofs(dofmap):
    """Local dofs of each local vertex (nv, 6; -1 where a vertex has a single side) and of each local cell
    (nc, 12; -1 beyond the cell's multipliers), from the section's layout (pfault.fields)."""
    sides = dofmap.vertex_dofs(0), dofmap.vertex_dofs(1)
    vdofs = np.concatenate([sides[0], np.where((dofmap.vert_sides > 1)[:, None], sides[1], -1)], axis=1)
    co = dofmap.cell_offset
    cdofs = np.full((len(co), CELL_COLUMNS), -1, dtype=np.int64)
    has = np.nonzero(co >= 0)[0]
    if len(has):
        # a cell's multipliers run up to the next point's first dof (points are laid out in chart order)
        starts = np.unique(np.concatenate([co[has], dofmap.vert_offset, [dofmap.n_local]]))
        count = starts[np.searchsorted(starts, co[has], side="right")] - co[has]
        k = np.arange(CELL_COLUMNS)
        cdofs[has] = np.where(k[None, :] < count[:, None], co[has][:, None] + k[None, :], -1)
    return vdofs, cdofs


def gather_local(mesh, dofmap, local):
    """A local array of the solution -> (vertex (N_v, 6), cell ids (k,), cell values (k, w)) in the serial
    numbering on rank 0 (None elsewhere): the cells that carry multipliers only, w their largest number.
    Collective."""
    vdofs, cdofs = point_dofs(dofmap)
    width = mesh.dm.getComm().tompi4py().allreduce(int(np.max((cdofs >= 0).sum(axis=1), initial=0)), op=MPI.MAX)
    v = np.where(vdofs >= 0, local[np.maximum(vdofs, 0)], 0.0)
    c = np.where(cdofs >= 0, local[np.maximum(cdofs, 0)], 0.0)[:, :width]
    count = (cdofs >= 0).sum(axis=1)[:, None].astype(float)
    vertex = distributed.gather_vertex_values(mesh, v)
    cell = distributed.gather_cell_values(mesh, np.concatenate([count, c], axis=1))
    if vertex is None:
        return None
    ids = np.nonzero(cell[:, 0] > 0)[0]
    return vertex, ids, cell[ids, 1:]


def scatter_local(mesh, dofmap, vertex, cell_ids, cell):
    """Inverse of gather_local on any partition: serial arrays (on every rank) -> local array."""
    vdofs, cdofs = point_dofs(dofmap)
    out = np.zeros(dofmap.n_local)
    v = vertex[mesh.vert_serial]
    out[vdofs[vdofs >= 0]] = v[vdofs >= 0]
    width = cell.shape[1] if cell.ndim == 2 else 0
    if width and len(cdofs):
        rows = np.full(mesh.n_global_cells, -1)
        rows[cell_ids] = np.arange(len(cell_ids))
        r = rows[mesh.cell_serial]
        mine = (cdofs[:, :width] >= 0) & (r >= 0)[:, None]
        out[cdofs[:, :width][mine]] = cell[np.maximum(r, 0)][:, :width][mine]
    return out


def _to_global(dm, local, gvec):
    lv = dm.getLocalVec()
    lv.setArray(local)
    dm.localToGlobal(lv, gvec, addv=PETSc.InsertMode.INSERT_VALUES)
    dm.restoreLocalVec(lv)


# ------------------------------------------------------------------------------------------------------
# writing
# ------------------------------------------------------------------------------------------------------
def gather(sim):
    """The state of ``sim`` (pfault.simulation.Simulation) in the serial numbering: {dataset path: array} on
    rank 0, None elsewhere. Collective."""
    p, mesh, dofmap = sim.problem, sim.mesh, sim.dofmap
    out = {}
    vecs = [("u", p.u), ("u_ref", p.u_ref)]
    if p.previous is not None:
        vecs.append(("u_previous", p.previous[1]))
        out["previous_time"] = p.previous[0]
    for name, vec in vecs:
        arrays = gather_local(mesh, dofmap, p.local_array(vec))
        if arrays is not None:
            out.update({f"{name}/vertex": arrays[0], f"{name}/cell_ids": arrays[1], f"{name}/cell": arrays[2]})
    if p.sigma0 is not None:
        out["sigma0"] = distributed.gather_cell_values(mesh, p.sigma0.reshape(-1, 9))
    if p.faults is not None:
        f = p.faults
        out["faults/t0"] = f.gather_faces(f.t0)
        out["faults/pn"] = f.gather_faces(f.pn)[:, 0]
    if sim.flow is not None:
        out["flow/head"] = distributed.gather_vertex_values(mesh, sim.flow.vertex_head().reshape(-1, 1))
        # a dataset, not an attribute: a long run's history outgrows HDF5's 64 KiB attribute limit
        out["flow/history"] = np.frombuffer(json.dumps(sim.flow.history).encode(), dtype=np.uint8)
        out["flow_time"] = float(sim.flow.time)
    return out if mesh.dm.getComm().getRank() == 0 else None


def write(directory, sim, step, t, state):
    """Write ``state`` (from ``gather``) as the checkpoint after step ``step`` at time t, whole
    (NAME.tmp, then renamed over the old one). Rank 0."""
    p, mesh = sim.problem, sim.mesh
    attrs = {"format": FORMAT, "step": int(step), "time_s": float(t), "scene": sim.settings.scene,
             "ranks": mesh.dm.getComm().getSize(), "nodes": int(mesh.n_global_vertices),
             "cells": int(mesh.n_global_cells), "fault_faces": int(len(sim.fault_id)) if sim.fault_settings else 0,
             "dofs": int(p.u.getSize()), "fields": json.dumps(list(sim.dofmap.fields)),
             "geostatic": bool(sim.settings.geostatic), "flow": sim.flow is not None}
    for key in ("flow_time", "previous_time"):
        if key in state:
            attrs[key] = state[key]
    path = os.path.join(directory, NAME)
    with open_h5(path + TMP_SUFFIX, "w") as h5:
        for key, value in attrs.items():
            h5.attrs[key] = value
        for name, data in state.items():
            if name not in ("flow_time", "previous_time"):
                h5.create_dataset(name, data=data)
    os.replace(path + TMP_SUFFIX, path)


# ------------------------------------------------------------------------------------------------------
# reading and restoring
# ------------------------------------------------------------------------------------------------------
def read(run_dir):
    """The checkpoint of a run directory as {"attrs": {...}, dataset path: array} (rank 0 calls it)."""
    path = os.path.join(run_dir, NAME)
    if not os.path.isfile(path):
        raise InputError(f"-pfault_restart {run_dir}: no {NAME} there (a run writes it after each completed "
                         "step)")
    try:
        with open_h5(path, "r") as h5:
            out = {"attrs": {k: (v.item() if hasattr(v, "item") else v) for k, v in h5.attrs.items()}}
            h5.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if hasattr(obj, "shape") else None)
    except OSError as exc:
        raise InputError(f"-pfault_restart {run_dir}: {NAME} is not readable ({exc})") from None
    if out["attrs"].get("format") != FORMAT:
        raise InputError(f"-pfault_restart {run_dir}: {NAME} has format {out['attrs'].get('format')}, this "
                         f"pfault reads {FORMAT}")
    return out


def check(ckpt, run_dir, sim):
    """InputError where the checkpoint does not belong to this scene and load (rank 0)."""
    run_options.check_options(run_dir, dict(PETSc.Options().getAll()), float(ckpt["attrs"]["time_s"]),
                              sim.settings.water_density, sim.settings.gravity)
    a = ckpt["attrs"]
    mine = {"nodes": int(sim.mesh.n_global_vertices), "cells": int(sim.mesh.n_global_cells),
            "fault_faces": int(len(sim.fault_id)) if sim.fault_settings else 0,
            "dofs": int(sim.problem.u.getSize()), "geostatic": bool(sim.settings.geostatic),
            "flow": sim.flow is not None}
    for key, value in mine.items():
        theirs = a.get(key)
        if (bool(theirs) if isinstance(value, bool) else theirs) != value:
            raise InputError(f"-pfault_restart {run_dir}: its checkpoint has {key} = {theirs}, this scene "
                             f"{value}; restart with the scene and mesh options of that run")


def restore(ckpt, sim):
    """Put the checkpoint's state into the problem (and flow model) of ``sim``; every rank holds ``ckpt``. The
    time loop then goes on as after the checkpoint's step: its next step's ``begin_step`` measures the faces'
    start from the restored u under the restored pore pressure."""
    p, mesh, dofmap = sim.problem, sim.mesh, sim.dofmap

    def vec(name, out):
        local = scatter_local(mesh, dofmap, ckpt[f"{name}/vertex"], ckpt[f"{name}/cell_ids"], ckpt[f"{name}/cell"])
        _to_global(p.dm, local, out)

    vec("u", p.u)
    vec("u_ref", p.u_ref)
    p.t_now = float(ckpt["attrs"]["time_s"])
    if "u_previous/vertex" in ckpt:
        prev = p.u.duplicate()
        vec("u_previous", prev)
        p._set_previous(ckpt["attrs"]["previous_time"], prev)
        prev.destroy()
    if "sigma0" in ckpt:
        p.sigma0 = ckpt["sigma0"][mesh.cell_serial].reshape(-1, 3, 3)
    if p.faults is not None:
        f = p.faults
        f.t0 = ckpt["faults/t0"][f.face].copy()
        f.set_pore_pressure(ckpt["faults/pn"][f.face])
    if sim.flow is not None:
        sim.flow.restore(ckpt["flow/head"][mesh.vert_serial], ckpt["attrs"]["flow_time"],
                         json.loads(bytes(ckpt["flow/history"]).decode()))


def load(comm, run_dir, sim):
    """Read the checkpoint on rank 0, check it, share it with every rank and restore it; returns its
    attributes. Collective; an InputError is raised on every rank together."""
    from ..errors import run_on_root

    def read_and_check():
        ckpt = read(run_dir)
        check(ckpt, run_dir, sim)
        return ckpt
    ckpt = run_on_root(comm, read_and_check)
    ckpt = comm.tompi4py().bcast(ckpt, root=0)
    restore(ckpt, sim)
    return ckpt["attrs"]
