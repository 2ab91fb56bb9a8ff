"""The state after the last completed step (``checkpoint.h5``), from which ``-pfault_restart DIR`` continues.

Written after every completed step, whole, into ``checkpoint.h5.tmp``, which then replaces the old one
(os.replace, by rank 0 once the file is closed): a checkpoint is either the previous one or the new one, never
half of each.

Every array is stored by mesh entity in the serial numbering, so a checkpoint does not depend on the
partition (a run on 2 ranks may continue on 1 or 3): per serial vertex, per serial cell or per serial fault
face. A vector's displacement dofs are 3 columns per side of the vertex with the most sides, at least 2 (6
columns: side 0, then the plus side of a split fault vertex; at a junction 3 more per further piece of its
star; zero where a vertex has fewer sides), its fault multipliers 3 per fault face (those of the face's minus
cell; zero on a penalty fault's face, which has none).

On more than one rank with h5py built with MPI (pfault.io.parallel.available, the test the field output
makes) every rank writes its rows (its owned vertices, its cells, the fault faces of its cells), moved first
into one contiguous block per rank, through HDF5's MPI-IO driver (pfault.io.parallel): no rank holds a whole
array. Otherwise the arrays are gathered to rank 0, which writes them. The files are the same either way.
A restart reads the attributes on rank 0 (the checks), then every rank reads the datasets.

What a run carries from one step to the next is its state (pfault.state.State): the solution u, the initial
state u_ref, the state converged before u, the initial stress sigma0, the equations' terms' histories (a fault's:
each face's initial traction, whether it has slid, whether it has broken and when) and the flow model's head, time
and records. The faces' stick/slip/open states are not state: the semismooth law reads them from u; the faces'
pore pressure is that of the checkpoint's time, set again on a restart. The Jacobian and its factorisation are
rebuilt at the first solve from the same values.

Contents (datasets; attributes on the root)
- ``u/vertex`` (serial vertices x 6, or 3 per side where junctions give vertices more than 2), ``u/face``
  (serial fault faces x 3; scenes with faults): the solution (displacements and fault multipliers) at the step's
  time
- ``u_ref/...``: the state at t = 0 (after the geostatic initial state)
- ``u_previous/...``, attribute ``previous_time``: the state converged before u (a fault scene's predictor
  extrapolates from it), when there is one
- ``sigma0`` (serial cells x 9, Pa): the geostatic initial stress, when there is one
- ``faults/t0`` (serial fault faces x 3, Pa, local frame): each face's initial traction; ``faults/slid`` (serial
  fault faces, 1 or 0): whether the face has slid (slipping or open at the end of a completed step, now or
  before), which decides whether its slip is reported; ``faults/broken`` (serial fault faces, 1 or 0) and
  ``faults/break_time`` (serial fault faces, s, NaN while intact): which faces of candidate surfaces have broken
  and when (pfault.faults.breaking; every face of a pre-existing fault is broken, without a time): the fault
  term's history (pfault.faults.term.FaultTerm.history_arrays)
- ``soils/stress0``, ``soils/stress``, ``soils/plastic_strain``, ``soils/strain`` (serial cells x 9) and
  ``soils/preconsolidation``, ``soils/branch`` (serial cells; zero outside the materials with memory): the memory
  of the materials with memory (pfault.soils.history.SoilMemory.arrays): the initial effective stress, the law's
  effective stress, plastic strain and preconsolidation p'_c at the checkpoint's state, the P1 strain of that state
  and the branch of each cell's last step
- ``flow/head`` (serial vertices, m), ``flow/history`` (its step records, JSON as bytes), attribute
  ``flow_time``
- ``steps``: the run's step records up to the checkpoint's step (JSON as bytes), those of summary.json: a run
  killed between its checkpoint and its summary continues from the checkpoint with its records
- ``input_files``: the data files the run read, each with its size and SHA-256 (JSON as bytes,
  pfault.provenance), which a restart compares with its own; absent from checkpoints of earlier versions of
  format 6 and before (their files are not checked)
- attributes ``format``, ``step``, ``time_s``, ``scene``, ``ranks``, ``nodes``, ``cells``, ``fault_faces``,
  ``dofs``, ``fields``, ``geostatic``, ``flow``

Format 7. Format 6 also has ``faults/pn`` and ``faults/traction`` (the faces' pore pressure and tractions, which
u and the loads of its time give): they are not read. Format 5 (without ``faults/broken`` and ``faults/break_time``)
is read with every face broken, without a time: the faults of the pfault that wrote it were all pre-existing.
Format 4 (without ``faults/slid``) is read for a scene without faults and refused with faults; format 3 (without
``faults/traction`` and ``steps``), 2 (multipliers per serial cell: ``u/cell_ids``, ``u/cell``) and 1 are refused.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np
from petsc4py import PETSc

from ..errors import InputError, PfaultError, run_on_all, run_on_root
from ..fields import LAGRANGE
from ..mesh import distributed
from ..sources import FlowState
from . import parallel, run_options
from .output import TMP_SUFFIX, open_h5

if TYPE_CHECKING:
    from ..fields import DofMap
    from ..mesh.distributed import LocalMesh
    from ..model import Model
    from ..state import State

FORMAT = 7                     # 6: faults/pn and faults/traction too; 5: no faults/broken; 4: no faults/slid;
                               # 3: no faults/traction; 2: multipliers per serial cell
NO_FAULT_SINCE = 4             # a checkpoint without faults reads the same since format 4
FAULTS_SINCE = 5               # a checkpoint with faults is read since format 5
NAME = "checkpoint.h5"
VERTEX, CELL, FACE = "vertex", "cell", "face"      # what a dataset's rows are


def vertex_dofs(dofmap: DofMap) -> np.ndarray:
    """Local dofs of each local vertex (nv, 3 * dofmap.max_sides): side 0, 1, ... (-1 where a vertex has fewer
    sides)."""
    return np.concatenate([np.where((dofmap.vert_sides > side)[:, None], dofmap.vertex_dofs(side), -1)
                           for side in range(dofmap.max_sides)], axis=1)


def _take(local, dofs):
    return np.where(dofs >= 0, local[np.maximum(dofs, 0)], 0.0)


def local_state(model: Model, state: State, step: int, t: float, records: list[dict[str, Any]]
                ) -> tuple[dict[str, tuple[str, np.ndarray]], dict[str, Any], dict[str, bytes]]:
    """This rank's part of ``state`` (pfault.state.State) of ``model`` (pfault.model.Model) after step ``step``
    at time t: ({dataset: (VERTEX, CELL or FACE, values per local vertex, local cell or owned fault face)}, root
    attributes, {dataset: JSON as bytes}: the step records ``records`` and the flow model's). The attributes and
    the JSON are the same on every rank. Collective."""
    mesh, dofmap, eq = model.mesh, model.dofmap, model.equations
    vdofs = vertex_dofs(dofmap)
    source = model.source
    attrs = {"format": FORMAT, "step": int(step), "time_s": float(t), "scene": model.settings.scene,
             "ranks": mesh.dm.getComm().getSize(), "nodes": int(mesh.n_global_vertices),
             "cells": int(mesh.n_global_cells), "fault_faces": int(model.faces.total),
             "dofs": int(state.u.getSize()), "fields": json.dumps(list(dofmap.fields)),
             "geostatic": bool(model.settings.geostatic), "flow": bool(source.has_state)}
    data = {}
    vecs = [("u", state.u), ("u_ref", state.u_ref)]
    if state.previous is not None:
        vecs.append(("u_previous", state.previous[1]))
        attrs["previous_time"] = float(state.previous[0])
    multipliers = LAGRANGE in dofmap.fields
    for name, vec in vecs:
        local = eq.local_array(vec)
        data[f"{name}/vertex"] = (VERTEX, _take(local, vdofs))
        if multipliers:
            data[f"{name}/face"] = (FACE, _take(local, model.faces.lm_dofs))
    if state.sigma0 is not None:
        data["sigma0"] = (CELL, np.asarray(state.sigma0, dtype=float).reshape(-1, 9))
    for term, history in zip(eq.terms, state.histories):
        for key, values in term.history_arrays(history).items():
            data[f"{term.name}/{key}"] = (term.rows, values)
    # datasets, not attributes: a long run's records outgrow HDF5's 64 KiB attribute limit
    texts = {"steps": json.dumps(records).encode()}
    if state.source_state is not None:
        flow = state.source_state
        data["flow/head"] = (VERTEX, np.asarray(flow.head, dtype=float))
        texts["flow/history"] = json.dumps(list(flow.history)).encode()
        attrs["flow_time"] = float(flow.time)
    return data, attrs, texts


# ------------------------------------------------------------------------------------------------------
# writing
# ------------------------------------------------------------------------------------------------------
class Writer:
    """Writes ``checkpoint.h5`` after each completed step: by every rank (``parallel``, see the module
    docstring) or gathered to rank 0. ``faces``: the serial ids of the fault faces this rank owns (None without
    faults). Every method is collective."""

    def __init__(self, comm: Any, mesh: LocalMesh, faces: np.ndarray, n_faces: int = 0,
                 parallel_io: bool = False, texts: dict[str, bytes] | None = None) -> None:
        self.mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
        self.mesh, self.parallel = mesh, bool(parallel_io)
        self.texts = dict(texts or {})      # JSON datasets written into every checkpoint (the run's data files)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.n_faces = int(n_faces)
        if not self.parallel:
            return
        own = np.flatnonzero(mesh.vert_owned)
        self.rows = {VERTEX: parallel.Rows(mesh.vert_serial[own], mesh.n_global_vertices, own),
                     CELL: parallel.Rows(mesh.cell_serial, mesh.n_global_cells)}
        if self.n_faces:
            self.rows[FACE] = parallel.Rows(self.faces, self.n_faces)
        self.blocks = parallel.blocks(self.mpi, NAME, self.rows)

    def write(self, directory: str, model: Model, state: State, step: int, t: float,
              records: list[dict[str, Any]]) -> None:
        """The checkpoint of ``state`` after step ``step`` at time t, with the run's step records up to it, into
        ``directory`` (known to every rank)."""
        data, attrs, texts = local_state(model, state, step, t, records)
        texts.update(self.texts)
        agreed = parallel.agree_shapes(self.mpi, {name: values for name, (_, values) in data.items()})
        data = {name: (kind, agreed[name]) for name, (kind, _) in data.items()}
        path = os.path.join(directory, NAME)
        if self.parallel:
            self._write_parallel(path, data, attrs, texts)
        else:
            arrays = self._gather(data)
            run_on_root(self.mpi, _write_serial, path, attrs, arrays, texts)

    # -- gathered to rank 0 -------------------------------------------------------------------------
    def _gather(self, data):
        """{dataset: array in the serial numbering} on rank 0, None elsewhere."""
        out = {}
        for name, (kind, values) in data.items():
            columns = parallel.as_columns(values)
            if kind == VERTEX:
                whole = distributed.gather_vertex_values(self.mesh, columns)
            elif kind == CELL:
                whole = distributed.gather_cell_values(self.mesh, columns)
            else:
                parts = self.mpi.gather((self.faces, columns), root=0)
                whole = None
                if parts is not None:
                    whole = np.zeros((self.n_faces, columns.shape[1]))
                    for faces, v in parts:
                        whole[faces] = v
            if whole is not None:
                out[name] = whole.reshape((len(whole),) + values.shape[1:])
        return out if self.mpi.rank == 0 else None

    # -- by every rank ------------------------------------------------------------------------------
    def _write_parallel(self, path, data, attrs, texts):
        blocks = {name: (self.blocks[kind].start,
                         self.blocks[kind].gather(self.mpi, self.rows[kind].pick(values)))
                  for name, (kind, values) in data.items()}
        shapes = {name: (self.rows[kind].total,) + values.shape[1:] for name, (kind, values) in data.items()}
        # rank 0's records (every rank has the same): their lengths are metadata, the same on every rank
        lengths = self.mpi.bcast({name: len(b) for name, b in texts.items()}, root=0)
        tmp = path + TMP_SUFFIX
        with _parallel_file(self.mpi, tmp) as h5:
            datasets = run_on_all(self.mpi, _create, h5, attrs, shapes, lengths)
            run_on_all(self.mpi, _fill, datasets, blocks, texts if self.mpi.rank == 0 else {})
        run_on_root(self.mpi, os.replace, tmp, path)


@contextmanager
def _parallel_file(comm, path):
    """``path`` created by every rank with the MPI-IO driver, and closed by every rank at the end (also after an
    error shared by every rank, which is raised then)."""
    h5 = run_on_all(comm, parallel.open_file, comm, path, "w")
    try:
        yield h5
    except PfaultError:
        try:
            run_on_all(comm, h5.close)
        except PfaultError:
            pass                # the first error is the one to tell
        raise
    run_on_all(comm, h5.close)


def _create(h5, attrs, shapes, lengths):
    """The attributes and the datasets (the same calls on every rank): {dataset path: dataset}; ``lengths``:
    of the JSON datasets."""
    for key, value in attrs.items():
        h5.attrs[key] = value
    datasets = {name: parallel.create_dataset(h5, name, shape, np.float64) for name, shape in shapes.items()}
    for name, n in lengths.items():
        datasets[name] = parallel.create_dataset(h5, name, (n,), np.uint8)
    return datasets


def _fill(datasets, blocks, texts):
    """This rank's block of every dataset; the JSON datasets from rank 0 (``texts`` there, empty elsewhere)."""
    for name, (start, values) in blocks.items():
        parallel.write_block(datasets[name], start, values)
    for name, b in texts.items():
        parallel.write_block(datasets[name], 0, np.frombuffer(b, dtype=np.uint8))


def _write_serial(path, attrs, arrays, texts):
    """Rank 0: the checkpoint from serial arrays, whole (NAME.tmp, then renamed over the old one)."""
    with open_h5(path + TMP_SUFFIX, "w") as h5:
        for key, value in attrs.items():
            h5.attrs[key] = value
        for name, data in arrays.items():
            h5.create_dataset(name, data=data)
        for name, b in texts.items():
            h5.create_dataset(name, data=np.frombuffer(b, dtype=np.uint8))
    os.replace(path + TMP_SUFFIX, path)


# ------------------------------------------------------------------------------------------------------
# reading and restoring
# ------------------------------------------------------------------------------------------------------
def _not_readable(run_dir, exc):
    return InputError(f"-pfault_restart {run_dir}: {NAME} is not readable ({exc})")


def read_attrs(run_dir: str) -> dict[str, Any]:
    """The root attributes of a run directory's checkpoint, once its format is checked (rank 0)."""
    path = os.path.join(run_dir, NAME)
    if not os.path.isfile(path):
        raise InputError(f"-pfault_restart {run_dir}: no {NAME} there (a run writes it after each completed "
                         "step)")
    try:
        with open_h5(path, "r") as h5:
            attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in h5.attrs.items()}
    except OSError as exc:
        raise _not_readable(run_dir, exc) from None
    fmt = attrs.get("format", 0)
    same = FAULTS_SINCE <= fmt <= FORMAT or (NO_FAULT_SINCE <= fmt < FORMAT and not attrs.get("fault_faces"))
    if not same:
        raise InputError(f"-pfault_restart {run_dir}: its {NAME} has format {attrs.get('format')}, written by "
                         f"another version of pfault; this one reads formats {FAULTS_SINCE} to {FORMAT} (continue that "
                         "run with the pfault that wrote it, or run it again)")
    return attrs


def read_datasets(run_dir: str) -> dict[str, np.ndarray]:
    """Every dataset of a run directory's checkpoint: {dataset path: array} (any rank)."""
    out: dict[str, np.ndarray] = {}
    try:
        with open_h5(os.path.join(run_dir, NAME), "r") as h5:
            h5.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if hasattr(obj, "shape") else None)
    except OSError as exc:
        raise _not_readable(run_dir, exc) from None
    return out


def check(attrs: dict[str, Any], run_dir: str, model: Model, state: State) -> None:
    """InputError where the checkpoint (its attributes) does not belong to this scene and load (rank 0)."""
    s = model.settings
    run_options.check_options(run_dir, dict(PETSc.Options().getAll()), float(attrs["time_s"]),
                              s.water_density, s.gravity)
    mine = {"nodes": int(model.mesh.n_global_vertices), "cells": int(model.mesh.n_global_cells),
            "fault_faces": int(model.faces.total),
            "dofs": int(state.u.getSize()), "geostatic": bool(s.geostatic),
            "flow": bool(model.source.has_state)}
    for key, value in mine.items():
        theirs = attrs.get(key)
        if (bool(theirs) if isinstance(value, bool) else theirs) != value:
            raise InputError(f"-pfault_restart {run_dir}: its checkpoint has {key} = {theirs}, this scene "
                             f"{value}; restart with the scene and mesh options of that run")


def restore(ckpt: dict[str, np.ndarray], attrs: dict[str, Any], model: Model, state: State) -> None:
    """Put the checkpoint's state ({dataset path: serial array}, ``attrs``) into ``state``; every rank holds
    them. The terms' histories start from the restored u under the loads of the checkpoint's time, as the time
    loop's next step would after the checkpoint's step."""
    mesh, dofmap, eq = model.mesh, model.dofmap, model.equations
    vdofs = vertex_dofs(dofmap)
    lm = model.faces.lm_dofs

    def vec(name, out):
        local = np.zeros(dofmap.n_local)
        v = ckpt[f"{name}/vertex"][mesh.vert_serial]
        local[vdofs[vdofs >= 0]] = v[vdofs >= 0]
        if f"{name}/face" in ckpt:
            local[lm[lm >= 0]] = ckpt[f"{name}/face"][model.faces.face][lm >= 0]
        eq.to_global(local, PETSc.InsertMode.INSERT_VALUES, out=out)

    vec("u", state.u)
    vec("u_ref", state.u_ref)
    state.time = float(attrs["time_s"])
    if "u_previous/vertex" in ckpt:
        prev = state.u.duplicate()
        vec("u_previous", prev)
        state.set_previous(attrs["previous_time"], prev)
        prev.destroy()
    if "sigma0" in ckpt:
        state.sigma0 = ckpt["sigma0"][mesh.cell_serial].reshape(-1, 3, 3)
    if model.source.has_state:
        state.source_state = FlowState(ckpt["flow/head"][mesh.vert_serial], float(attrs["flow_time"]),
                                       tuple(json.loads(bytes(ckpt["flow/history"]).decode())))
        model.source.restore(state.source_state)
    eq.loads.set(state.time)        # the terms' loads of the checkpoint's time: their start reads them
    x_loc = eq.local_array(state.u)
    rows = {FACE: model.faces.face, CELL: mesh.cell_serial}
    histories = []
    for term, load in zip(eq.terms, eq.loads.term_loads):
        prefix = term.name + "/"
        arrays = {key[len(prefix):]: values[rows[term.rows]] for key, values in ckpt.items()
                  if key.startswith(prefix)}
        histories.append(term.restored(arrays, x_loc, load))
    state.histories = tuple(histories)


def load(comm: Any, run_dir: str, model: Model, state: State) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Check the checkpoint of ``run_dir`` on rank 0, read it on every rank and restore it into ``state``;
    returns its attributes and the run's step records up to its step. Collective; an InputError is raised on
    every rank together."""

    def read_and_check():
        attrs = read_attrs(run_dir)
        check(attrs, run_dir, model, state)
        return attrs
    attrs = comm.tompi4py().bcast(run_on_root(comm, read_and_check), root=0)
    ckpt = run_on_all(comm, read_datasets, run_dir)
    restore(ckpt, attrs, model, state)
    return attrs, json.loads(bytes(ckpt["steps"]).decode())
