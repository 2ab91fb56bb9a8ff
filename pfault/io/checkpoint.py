"""The state after the last completed step (``checkpoint.h5``), from which ``-pfault_restart DIR`` continues.

Written after every completed step, whole, into ``checkpoint.h5.tmp`` and then renamed over the old one: a
checkpoint is either the previous one or the new one, never half of each.

Vectors are stored by mesh point in the serial numbering, so a checkpoint does not depend on the partition
(a run on 2 ranks may continue on 1 or 3): per serial vertex its displacement dofs (6 columns: side 0, then
the plus side of a split fault vertex, zero elsewhere) and, for the serial cells that carry fault multipliers
(``cell_ids``), their multipliers (3 per fault face the cell owns, zero-padded to the widest cell).

Contents (datasets; attributes on the root)
- ``u/vertex``, ``u/cell_ids``, ``u/cell``: the solution (displacements and fault multipliers) at the step's
  time
- ``u_ref/...``: the state at t = 0 (after the geostatic initial state)
- ``sigma0`` (cells x 9, Pa): the geostatic initial stress, when there is one
- ``fault_state`` (serial fault faces): stick/slip/open at the end of the step
- ``predictor/...``, attributes ``predictor_t0``, ``predictor_t1``: the state at the
  start of the step, which the augmented slip direction's predictor extrapolates from
- ``flow/head`` (serial vertices, m), ``flow/history`` (its step records, JSON as bytes), attribute
  ``flow_time``
- attributes ``format``, ``step``, ``time_s``, ``scene``, ``ranks``, ``nodes``, ``cells``, ``fault_faces``,
  ``dofs``, ``fields``, ``geostatic``, ``flow``, ``slip_direction``
"""

from __future__ import annotations

import json
import os

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ..errors import InputError
from ..mesh import distributed
from .output import TMP_SUFFIX, open_h5

FORMAT = 1
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
# the solver state a run keeps between steps beyond the solution vector
# ------------------------------------------------------------------------------------------------------
def _predictor_state(problem):
    """(state at the start of the last converged step, its start time, its end time) kept by a fault problem
    for the augmented slip direction's predictor, or None."""
    last = getattr(problem, "_last", None)
    return last if last is not None and getattr(problem, "_t_state", None) == last[2] else None


def _restore_predictor(problem, vec, t0, t1):
    old = getattr(problem, "_last", None)
    if old is not None:
        old[0].destroy()
    problem._last = (vec, float(t0), float(t1))
    problem._t_state = float(t1)


# ------------------------------------------------------------------------------------------------------
# writing
# ------------------------------------------------------------------------------------------------------
def write(directory, sim, step, t):
    """Write the checkpoint of ``sim`` (pfault.simulation.Simulation) after step ``step`` at time t.
    Collective; rank 0 writes."""
    p, mesh, dofmap = sim.problem, sim.mesh, sim.dofmap
    comm = mesh.dm.getComm()
    arrays = {}
    for name, vec in (("u", p.u), ("u_ref", p.u_ref)):
        arrays[name] = gather_local(mesh, dofmap, p.local_array(vec))
    sigma0 = None
    if p.sigma0 is not None:
        sigma0 = distributed.gather_cell_values(mesh, p.sigma0.reshape(-1, 9))
    state = None
    attrs = {}
    if sim.fault_settings:
        state = p.faults.gather_faces(p.faults.state.astype(float))[:, 0].astype(np.int64)
        attrs["slip_direction"] = p.slip_direction
        last = _predictor_state(p)
        if last is not None:
            arrays["predictor"] = gather_local(mesh, dofmap, p.local_array(last[0]))
            attrs["predictor_t0"], attrs["predictor_t1"] = float(last[1]), float(last[2])
    head = None
    if sim.flow is not None:
        head = distributed.gather_vertex_values(mesh, sim.flow.vertex_head().reshape(-1, 1))
        attrs["flow_time"] = float(sim.flow.time)
        # a dataset, not an attribute: a long run's history outgrows HDF5's 64 KiB attribute limit
        flow_history = np.frombuffer(json.dumps(sim.flow.history).encode(), dtype=np.uint8)
    if comm.rank != 0:
        return
    attrs.update({"format": FORMAT, "step": int(step), "time_s": float(t), "scene": sim.settings.scene,
                  "ranks": comm.size, "nodes": int(mesh.n_global_vertices), "cells": int(mesh.n_global_cells),
                  "fault_faces": int(len(sim.fault_id)) if sim.fault_settings else 0, "dofs": int(p.u.getSize()),
                  "fields": json.dumps(list(dofmap.fields)), "geostatic": bool(sim.settings.geostatic),
                  "flow": sim.flow is not None})
    path = os.path.join(directory, NAME)
    with open_h5(path + TMP_SUFFIX, "w") as h5:
        for key, value in attrs.items():
            h5.attrs[key] = value
        for name, (vertex, cell_ids, cell) in arrays.items():
            h5.create_dataset(f"{name}/vertex", data=vertex)
            h5.create_dataset(f"{name}/cell_ids", data=cell_ids)
            h5.create_dataset(f"{name}/cell", data=cell)
        if sigma0 is not None:
            h5.create_dataset("sigma0", data=sigma0)
        if state is not None:
            h5.create_dataset("fault_state", data=state)
        if head is not None:
            h5.create_dataset("flow/head", data=head[:, 0])
            h5.create_dataset("flow/history", data=flow_history)
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
    """InputError where the checkpoint does not belong to this scene (rank 0)."""
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
    """Put the checkpoint's state into the problem (and flow model) of ``sim``; every rank holds ``ckpt``."""
    p, mesh, dofmap = sim.problem, sim.mesh, sim.dofmap
    a = ckpt["attrs"]

    def vec(name, out=None):
        local = scatter_local(mesh, dofmap, ckpt[f"{name}/vertex"], ckpt[f"{name}/cell_ids"], ckpt[f"{name}/cell"])
        g = out if out is not None else p.u.duplicate()
        _to_global(p.dm, local, g)
        return g

    vec("u", p.u)
    vec("u_ref", p.u_ref)
    if "sigma0" in ckpt:
        p.sigma0 = ckpt["sigma0"][mesh.cell_serial].reshape(-1, 3, 3)
    if sim.fault_settings:
        f = p.faults
        if p.sigma0 is not None:
            f.t0 = f.initial_tractions(p.sigma0)       # as the geostatic initial state sets them
        # the configuration at the end of the step: the next step starts from it (its begin_step turns
        # slipping faces to stick unless the predictor carries them on)
        f.state = ckpt["fault_state"][f.face].astype(f.state.dtype)
        if a.get("slip_direction") == "increment" and p.slip_direction != "increment":
            f.c_slip = None                              # the augmented direction had failed for good
        if "predictor/vertex" in ckpt:
            _restore_predictor(p, vec("predictor"), a["predictor_t0"], a["predictor_t1"])
        elif hasattr(p, "_t_state"):
            p._t_state = float(a["time_s"])
    if sim.flow is not None:
        sim.flow.restore(ckpt["flow/head"][mesh.vert_serial], a["flow_time"],
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
