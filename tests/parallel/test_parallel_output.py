"""Output written by every rank (pfault.io.parallel) against the serial writer, from the same values.

tests/scripts/parallel_output.py runs a small fault scene with groundwater flow (Queretaro at size factor 6:
displacement with split fault vertices, head change, pore-pressure change, stress, the fault's per-face fields,
the land surface) and writes every output step twice: through the run's own output, which on 2 ranks is
written in parallel, and through the writer that gathers the fields to rank 0 and writes them there. The two
are compared dataset by dataset (np.array_equal: the same values, shapes, dtypes and attributes), the XDMF
files text for text, and the parallel run's series read back through meshio's TimeSeriesReader.
"""

import os

import numpy as np
import pytest

from conftest import QUERETARO, run_script

QRO = [QUERETARO, "-pfault_mesh_size_factor", "6", "-pfault_time_steps", "2", "-pfault_time_end",
       "2*year", "-pfault_figures", "false"]


def _datasets(path):
    import h5py
    out = {}
    with h5py.File(path, "r") as h5:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj[()], dict(obj.attrs))
            else:
                out[name] = (None, dict(obj.attrs))
        h5.visititems(visit)
    return out


@pytest.mark.parametrize("ranks", [1, 2])
def test_parallel_output_equals_the_serial_writer(tmp_path, ranks):
    par, gathered = tmp_path / "run", tmp_path / "gathered"
    info = run_script("parallel_output.py", ranks=ranks,
                      args=[QRO[0], str(gathered), *QRO[1:], "-pfault_output_dir", str(par)])
    if ranks > 1 and not info["h5py_mpi"]:
        pytest.skip("h5py without MPI: the fields are gathered to rank 0")
    assert info["parallel"] == (ranks > 1)
    if ranks > 1:           # every rank writes a block, and rows move between the ranks to get there
        for name in ("fields", "fault"):
            per_rank = info["blocks"][name]["Cell"]
            assert min(n for n, _ in per_rank) > 0 and sum(o for _, o in per_rank) > 0, (name, per_rank)
    for name in ("fields", "fault", "surface"):
        a, b = _datasets(par / f"{name}.h5"), _datasets(gathered / f"{name}.h5")
        assert sorted(a) == sorted(b), name
        assert any(key.startswith("steps/000002/") for key in a), name
        for key in a:
            (x, xa), (y, ya) = a[key], b[key]
            assert xa == ya, (name, key)
            if x is not None:
                # (NaN: an intact face's break time, in the same places)
                assert x.dtype == y.dtype and x.shape == y.shape, (name, key)
                assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), (name, key)
        assert (par / f"{name}.xdmf").read_text() == (gathered / f"{name}.xdmf").read_text(), name

    import meshio
    with meshio.xdmf.TimeSeriesReader(str(par / "fields.xdmf")) as reader:
        points, _ = reader.read_points_cells()
        assert reader.num_steps == 3
        t, point_data, cell_data = reader.read_data(2)
    steps = _datasets(par / "fields.h5")
    assert len(points) == len(steps["mesh/points"][0])
    assert np.array_equal(point_data["displacement"], steps["steps/000002/displacement"][0])
    assert np.array_equal(point_data["head_change"], steps["steps/000002/head_change"][0])
    assert np.array_equal(cell_data["stress"][0], steps["steps/000002/stress"][0])
    assert np.abs(point_data["displacement"]).max() > 1e-3      # a field that moved, not zeros
    with meshio.xdmf.TimeSeriesReader(str(par / "fault.xdmf")) as reader:
        reader.read_points_cells()
        assert reader.num_steps == 3
        _, _, fault = reader.read_data(2)
    assert np.array_equal(fault["slip"][0], _datasets(par / "fault.h5")["steps/000002/slip"][0])
    assert os.path.exists(par / "summary.json")


@pytest.mark.parametrize("ranks", [2, 3])
def test_parallel_checkpoint_equals_the_gathered_one(tmp_path, ranks):
    """tests/scripts/parallel_checkpoint.py on the same fault scene with flow (split vertices, Lagrange
    multipliers, geostatic stress, the previous state, the head and its records): after every step
    the checkpoint the run writes in parallel and one gathered to rank 0 from the same state are the same file,
    attribute for attribute and value for value."""
    par, gathered, own = tmp_path / "run", tmp_path / "gathered", tmp_path / "own"
    info = run_script("parallel_checkpoint.py", ranks=ranks,
                      args=[QRO[0], str(gathered), str(own), *QRO[1:], "-pfault_output_dir", str(par)])
    if not info["h5py_mpi"]:
        pytest.skip("h5py without MPI: the checkpoint is gathered to rank 0")
    assert info["parallel"] and info["steps"] == [1, 2]
    # every rank writes a block of each kind of row, and rows move between the ranks to get there
    assert sorted(info["blocks"]) == ["cell", "face", "vertex"]
    for kind, per_rank in info["blocks"].items():
        assert len(per_rank) == ranks and min(n for n, _ in per_rank) > 0, (kind, per_rank)
        assert sum(o for _, o in per_rank) > 0, (kind, per_rank)
    for step in info["steps"]:
        a, b = _datasets(own / str(step) / "checkpoint.h5"), _datasets(gathered / str(step) / "checkpoint.h5")
        assert sorted(a) == sorted(b) == [
            "faults", "faults/break_time", "faults/broken", "faults/slid", "faults/t0",
            "flow", "flow/head", "flow/history", "input_files", "sigma0",
            "steps", "u", "u/face", "u/vertex", "u_previous", "u_previous/face", "u_previous/vertex", "u_ref",
            "u_ref/face", "u_ref/vertex"], step
        for key in a:
            (x, xa), (y, ya) = a[key], b[key]
            assert xa == ya, (step, key)
            if x is not None:
                assert x.dtype == y.dtype and x.shape == y.shape, (step, key)
                assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), (step, key)
        import h5py
        with h5py.File(own / str(step) / "checkpoint.h5", "r") as x, \
                h5py.File(gathered / str(step) / "checkpoint.h5", "r") as y:
            assert dict(x.attrs) == dict(y.attrs)
            assert x.attrs["step"] == step and x.attrs["ranks"] == ranks and x.attrs["format"] == 7
            # values that moved: slipping faces' multipliers, the head, the displacement
            assert np.abs(x["u/face"][:, 1:]).max() > 1e3 and np.abs(x["flow/head"][()]).max() > 1.0
            assert np.abs(x["u/vertex"][()]).max() > 1e-2
    assert not [f for f in os.listdir(par) if f.endswith(".tmp")]
