"""The suite's runs of pfault (tests/inprocess.py): one in the test process (1 rank) or in the MPI workers (2 ranks)
is the run a new process makes, to the bit; no option and no PETSc object of one run is left for the next; a run
that would hang fails its test."""

import gc
import os
import re

import pytest
from petsc4py import PETSc

from conftest import OEDOMETER, REPO, TWO_BLOCKS, WORKERS, compare_runs, run, run_scene, run_script, write_flow_box


def alive_objects():
    """PETSc objects alive in this process, by type (created less destroyed, from PETSc's log)."""
    gc.collect()
    path = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"pfault-log-{os.getpid()}.txt")
    viewer = PETSc.Viewer().createASCII(path)
    PETSc.Log.view(viewer)
    viewer.destroy()
    with open(path) as fh:
        table = fh.read().partition("Object Type")[2]
    os.remove(path)
    counts = {}
    for line in table.splitlines():
        m = re.match(r"^\s+([A-Za-z][A-Za-z ]*?)\s+(\d+)\s+(\d+)\b", line)
        if m:
            counts[m.group(1)] = counts.get(m.group(1), 0) + int(m.group(2)) - int(m.group(3))
    return {k: v for k, v in counts.items() if v and k != "Viewer"}


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("scene", ["two_blocks", "flow_box"])
def test_a_run_here_is_the_run_of_a_new_process(tmp_path, scene, ranks):
    """The two blocks (faults, slip) and the flow box (groundwater flow): every dataset of every output step and
    the summary's maxima equal to the bit, the same Newton iterations, partitioned alike on 2 ranks (pfault resets
    the partitioner's random state: without it a second run in one process was partitioned otherwise)."""
    opts = write_flow_box(tmp_path) if scene == "flow_box" else TWO_BLOCKS
    extra = ["-pfault_time_end", "1*day", "-pfault_time_steps", "2"] if scene == "flow_box" else []
    _, here = run_scene(opts, tmp_path / "here", ranks=ranks, extra=extra)
    _, again = run_scene(opts, tmp_path / "again", ranks=ranks, extra=extra)
    proc, new = run_scene(opts, tmp_path / "new", ranks=ranks, extra=extra, here=False)
    assert new["ranks"] == here["ranks"] == ranks
    # on 1 rank to the bit; on 2 to round-off, as two new processes (measured 3.8e-15 apart on the two blocks)
    for other in (tmp_path / "here", tmp_path / "again"):
        assert compare_runs(str(tmp_path / "new"), str(other), 0.0 if ranks == 1 else 1e-13) <= 1e-13
    assert [r["newton_its"] for r in here["steps"]] == [r["newton_its"] for r in new["steps"]]


def test_the_workers_partition_as_a_new_process():
    """The MPI workers partition a scene as a new process does (tests/scripts/fault_partition.py), run after run:
    pfault resets PT-Scotch's random state before each partition (without it, every run after the first in a process was
    partitioned otherwise: 892/836 cells instead of 836/892 on the two blocks at 8x6x6)."""
    options = [TWO_BLOCKS, "-pfault_box_cells", "8,6,6", "-pfault_output_dir", "unused"]
    new = run_script("fault_partition.py", ranks=2, args=options[1:3])["cell_ranks"]
    assert len(set(new)) == 2
    for _ in range(2):
        assert WORKERS.cell_ranks(options, 2, REPO, 120) == new


def test_no_option_of_a_run_is_left_for_the_next(tmp_path):
    """A run with the conjugate gradient, then one without: the second has the solver file's Krylov method; the
    options database is empty after each (as the test process started it)."""
    _, cg = run_scene(OEDOMETER, tmp_path / "cg", extra=["-pfault_solver", "iterative", "-ksp_type", "cg"])
    assert PETSc.Options().getAll() == {}
    _, plain = run_scene(OEDOMETER, tmp_path / "plain", extra=["-pfault_solver", "iterative"])
    assert PETSc.Options().getAll() == {}
    assert cg["solver"]["ksp_type"] == "cg" and plain["solver"]["ksp_type"] != "cg"


def test_a_run_leaves_no_petsc_object(tmp_path, flow_box):
    """The oedometer and the flow box destroy every PETSc object they make, whether the run ends well or with
    an input error."""
    PETSc.Log.begin()
    before = alive_objects()
    run_scene(OEDOMETER, tmp_path / "oed")
    run_scene(flow_box, tmp_path / "flow", extra=["-pfault_time_end", "1*day", "-pfault_time_steps", "2"])
    proc, _ = run_scene(OEDOMETER, tmp_path / "bad", extra=["-ksp_rtoll", "1"], check=False)
    assert proc.returncode == 1
    assert alive_objects() == before


@pytest.mark.xfail(strict=True, reason="a scene with faults leaves one ISLocalToGlobalMapping that no Python object "
                   "holds (PETSc 3.18; a few bytes per unknown): left for the faults' own work")
def test_a_run_with_faults_leaves_no_petsc_object(tmp_path):
    PETSc.Log.begin()
    before = alive_objects()
    run_scene(TWO_BLOCKS, tmp_path / "blocks")
    assert alive_objects() == before


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_run_past_its_timeout_fails_its_test_and_the_next_run_goes_on(tmp_path, ranks):
    """A 60-step run given 0.5 s: the test fails (the workers are stopped, the run here ends as an internal error
    naming the timeout); the next run is made as usual."""
    slow = ["-pfault_box_cells", "4,4,40", "-pfault_time_steps", "60"]
    with pytest.raises(pytest.fail.Exception, match="did not end within 0.5 s") if ranks == 2 else \
            pytest.raises(AssertionError, match="RunTimeout: the run went past its timeout of 0.5 s"):
        run(["-m", "pfault", OEDOMETER, "-pfault_output_dir", str(tmp_path / "slow"), *slow], ranks=ranks,
            timeout=0.5)
    _, s = run_scene(OEDOMETER, tmp_path / "next", ranks=ranks)
    assert s["converged"] and s["ranks"] == ranks
