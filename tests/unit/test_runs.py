"""pfault.tools.runs, the one runner of pfault processes: a run past its timeout is killed with what it started,
a logged run keeps its output and exit code, and a run imports this checkout's pfault."""

import os
import subprocess
import sys
import time

import pytest

from pfault.tools import runs

# a child that starts a grandchild sleeping for a minute, prints the grandchild's pid, then sleeps itself
PARENT = ("import subprocess, sys, time; p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']); "
          "print(p.pid, flush=True); time.sleep(60)")


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as fh:          # a zombie waiting for its parent is not running
        return fh.read().split()[2] != "Z"


def test_a_run_past_its_timeout_is_killed_with_what_it_started(tmp_path):
    t0 = time.perf_counter()
    with pytest.raises(subprocess.TimeoutExpired) as err:
        runs.run_captured(["-c", PARENT], timeout=10, cwd=str(tmp_path))
    assert time.perf_counter() - t0 < 40
    grandchild = int(err.value.stdout.split()[0])
    deadline = time.time() + 10
    while _alive(grandchild) and time.time() < deadline:
        time.sleep(0.1)
    assert not _alive(grandchild)


def test_a_logged_run_keeps_its_output_code_and_times(tmp_path):
    log = tmp_path / "sub" / "run.log"
    done = runs.run_logged(["-c", "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"], 1,
                           str(log), timeout=60, cwd=str(tmp_path))
    assert (done.code, done.timed_out) == (3, False)
    assert sorted(done.output.split()) == ["err", "out"]
    assert done.wall > 0 and done.cpu >= 0 and done.load >= 0
    stopped = runs.run_logged(["-c", "import time; time.sleep(60)"], 1, str(tmp_path / "slow.log"), timeout=1,
                              cwd=str(tmp_path))
    assert stopped.timed_out and stopped.code == -9 and stopped.wall < 30


def test_a_run_imports_this_pfault_from_any_directory(tmp_path):
    proc = runs.run_captured(["-c", "import pfault; print(pfault.__file__)"], cwd=str(tmp_path), timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert os.path.dirname(os.path.dirname(proc.stdout.strip())) == runs.SOURCE_ROOT


def test_commands_on_one_and_more_ranks():
    assert runs.command(["-m", "pfault", "a.opts"], 1) == [sys.executable, "-m", "pfault", "a.opts"]
    many = runs.command(["x.py"], 2 * (os.cpu_count() or 1))
    assert many[:3] == ["mpirun", "-n", str(2 * (os.cpu_count() or 1))] and "--oversubscribe" in many
    run = runs.Run("config/oedometer.opts", "out", {"pfault_time_steps": 2}, ranks=2)
    assert runs.command(runs.pfault_args(run), run.ranks)[:3] == ["mpirun", "-n", "2"]
    assert runs.pfault_args(run)[-2:] == ["-pfault_time_steps", "2"]


def test_a_run_does_not_inherit_an_mpi_launch_context(tmp_path):
    """A run started from a process with a started MPI (whose PMIx server variables it would inherit) is a new
    MPI job: the launcher's variables are left out, the user's Open MPI settings kept."""
    base = {"PATH": os.environ["PATH"], "PMIX_SERVER_URI41": "x", "OMPI_MCA_ess": "singleton",
            "OMPI_COMM_WORLD_RANK": "0", "OMPI_MCA_btl_vader_single_copy_mechanism": "none", "HOME": "/root"}
    env = runs.environment(base)
    assert not any(k.startswith(("PMIX_", "OMPI_MCA_ess", "OMPI_COMM_WORLD")) for k in env)
    assert env["OMPI_MCA_btl_vader_single_copy_mechanism"] == "none" and env["HOME"] == "/root"
    proc = runs.run_captured(["-c", "print('ok')"], ranks=2, cwd=str(tmp_path),
                             env=runs.environment(dict(os.environ, **base)), timeout=120)
    assert proc.returncode == 0 and proc.stdout.split() == ["ok", "ok"], proc.stderr
