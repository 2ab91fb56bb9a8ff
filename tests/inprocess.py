"""pfault's command line run in a PETSc that is already running: on one rank in the test process, on more ranks in
a set of MPI workers started once (``python tests/inprocess.py`` under mpirun).

``python -m pfault ...`` costs a second or more of every rank's time before its first mesh (the interpreter,
petsc4py, NumPy, h5py, meshio and gmsh imported, MPI started), and most of the suite's runs are smaller than that.
Here each run goes through ``pfault.__main__.main``, the command line's own code, which replaces PETSc's options
database by the scene's and the run's options (pfault.__main__.start_petsc): no option carries over from one run
to the next. The run destroys what it made (pfault.cli.main); the database is emptied after it (and pfault resets
the partitioner's random state before it partitions: pfault.mesh.distributed.reset_partitioner_random_state), so
that a run is partitioned as in a new process. What the run prints, from
Python or from C (PETSc prints through C stdio), is captured from the file descriptors as a process's output would
be; the run has a timeout; the exit code is main's (for more ranks, the first non-zero of the ranks', as mpirun's).

A worker set serves one run at a time: rank 0 reads a request (JSON, one line) from its standard input (mpirun
passes it on), every rank runs it with its output in files beside the request's, and rank 0 answers on its
standard output. Between runs the ranks wait without spinning (a non-blocking barrier polled every few
milliseconds), so that idle workers leave the cores to the test process. A run past its timeout, or one that
ends the workers (an error on some ranks only aborts the MPI job, as it should), fails its test; the next run
starts a new set.

Runs that are about the process itself (signals, an abort, -log_view and the other options PETSc reads only when it
starts or ends) are made as processes (conftest.run, ``can_run_here``).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import json
import os
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence

# options that take effect only when PETSc starts or ends (PetscInitialize, PetscFinalize)
START_OPTIONS = ("-log_view", "-log_summary", "-log_trace", "-malloc", "-memory_view", "-objects_dump",
                 "-options_left", "-on_error_abort", "-start_in_debugger", "-help")
ANSWER = "pfault-worker: "
POLL = 0.005                    # s between tests of the barrier that starts a run on every rank
_LIBC = ctypes.CDLL(None)
RUNS_HERE = [0, 0]              # runs made in this process, and in MPI workers (conftest's summary line)


def can_run_here(args: Sequence[object]) -> bool:
    """Whether ``python ARGS`` is pfault's command line with no option that only a new PETSc would read."""
    args = [str(a) for a in args]
    if args[:2] != ["-m", "pfault"]:
        return False
    if len(args) == 2 or args[2].startswith("-"):
        return True                 # no scene: help or a usage error, before PETSc
    return not any(a.startswith(START_OPTIONS) for a in args[3:])


# ------------------------------------------------------------------------------------------------------
# one run, on every rank of the running PETSc
# ------------------------------------------------------------------------------------------------------
def _flush() -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    _LIBC.fflush(None)


@contextlib.contextmanager
def redirected(out, err) -> Iterator[None]:
    """File descriptors 1 and 2 (C stdio, and Python's sys.stdout and sys.stderr) into the files ``out`` and
    ``err`` inside the block."""
    _flush()
    saved = [os.dup(1), os.dup(2)]
    python = sys.stdout, sys.stderr
    try:
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        sys.stdout = open(1, "w", closefd=False, buffering=1, encoding="utf-8", errors="replace")
        sys.stderr = open(2, "w", closefd=False, buffering=1, encoding="utf-8", errors="replace")
        yield
    finally:
        _flush()
        sys.stdout.close()
        sys.stderr.close()
        sys.stdout, sys.stderr = python
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


class RunTimeout(Exception):
    """A run in this process went past its timeout (raised in it by SIGALRM)."""


@contextlib.contextmanager
def deadline(seconds: float | None) -> Iterator[None]:
    """RunTimeout raised in the block after ``seconds`` (SIGALRM); the SIGINT handler the block may change (gmsh
    resets it when it starts) is put back after it."""
    def ring(signum, frame):
        raise RunTimeout(f"the run went past its timeout of {seconds:g} s")
    interrupt = signal.getsignal(signal.SIGINT)
    previous = signal.signal(signal.SIGALRM, ring) if seconds else None
    if seconds:
        signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        if seconds:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
        signal.signal(signal.SIGINT, interrupt)


def run_main(args: Sequence[str], cwd: str, timeout: float | None) -> int:
    """pfault.__main__.main on ``python ARGS`` from ``cwd``, on every rank; its exit code. The options database is
    left empty, as the process started it, and the garbage collected (on every rank at once)."""
    from petsc4py import PETSc

    from pfault import __main__ as pfault_main
    from pfault.optionsfile import replace_database
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with deadline(timeout):
            return pfault_main.main(["pfault", *map(str, args[2:])])
    finally:
        os.chdir(here)
        replace_database(PETSc.Options(), [])
        gc.collect()


def run_here(args: Sequence[object], cwd: str, timeout: float | None = None) -> subprocess.CompletedProcess:
    """``python ARGS`` (pfault's command line, ``can_run_here``) run in this process (one rank); the
    CompletedProcess a process would give. A run past ``timeout`` ends as an internal error (exit 6) with
    RunTimeout named in its stderr."""
    args = [str(a) for a in args]
    RUNS_HERE[0] += 1
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        with redirected(out, err):
            code = run_main(args, cwd, timeout)
        texts = []
        for fh in (out, err):
            fh.seek(0)
            texts.append(fh.read().decode("utf-8", errors="replace"))
    return subprocess.CompletedProcess(args, code, *texts)


# ------------------------------------------------------------------------------------------------------
# MPI workers
# ------------------------------------------------------------------------------------------------------
def serve() -> None:
    """The workers' loop (``mpirun -n N python tests/inprocess.py``): a request {"args", "cwd", "capture",
    "timeout"} per line on rank 0's stdin; each rank's stdout and stderr of the run go to CAPTURE.RANK.out and
    .err; rank 0 answers {"codes": [every rank's exit code]} on a line starting with ANSWER."""
    import petsc4py
    petsc4py.init([sys.argv[0]])
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    answer = os.dup(1)
    while True:
        line = sys.stdin.readline() if comm.rank == 0 else None
        started = comm.Ibarrier()
        while not started.Test():
            time.sleep(POLL)
        request = comm.bcast(line, root=0)
        if not request:
            return
        req = json.loads(request)
        capture = f"{req['capture']}.{comm.rank}"
        reply = {}
        with open(capture + ".out", "w") as out, open(capture + ".err", "w") as err:
            with redirected(out, err):
                try:
                    if "partition" in req:
                        reply["cell_ranks"] = cell_ranks(req["partition"], req["cwd"])
                        code = 0
                    else:
                        code = run_main(req["args"], req["cwd"], None)
                except BaseException as exc:  # noqa: BLE001  (main turns every error into a code: not reached)
                    sys.stderr.write(f"worker: {exc!r}\n")
                    code = 99
        reply["codes"] = comm.gather(code, root=0)
        if comm.rank == 0:
            os.write(answer, (ANSWER + json.dumps(reply) + "\n").encode())


def cell_ranks(args: Sequence[str], cwd: str) -> list[int] | None:
    """The rank of every cell (serial order; on rank 0, None on the others) of the scene ``args`` (scene file,
    options) as a run here partitions it: the model built and destroyed, nothing solved (the workers' check that a
    run here is partitioned as in a new process, tests/cli/test_runs_here.py)."""
    import numpy as np
    from petsc4py import PETSc

    from pfault.optionsfile import petsc_arguments, replace_database
    from pfault.simulation import Simulation
    here = os.getcwd()
    os.chdir(cwd)
    try:
        replace_database(PETSc.Options(), petsc_arguments(args[0], list(args[1:])))
        sim = Simulation(args[0], ["pfault", *args])
        owned = sim.comm.tompi4py().gather(sim.model.mesh.cell_serial, root=0)
        sim.destroy()
    finally:
        os.chdir(here)
        replace_database(PETSc.Options(), [])
    if owned is None:
        return None
    ranks = np.zeros(sum(len(ids) for ids in owned), int)
    for r, ids in enumerate(owned):
        ranks[ids] = r
    return ranks.tolist()


class Workers:
    """The test process's side: one worker set per rank count, started on first use, each run under a
    timeout."""

    def __init__(self, env: dict, cwd: str) -> None:
        self.env, self.cwd = env, cwd
        self.sets: dict[int, subprocess.Popen] = {}
        self.dir = tempfile.mkdtemp(prefix="pfault-workers-")
        self.count = 0

    def _start(self, ranks: int) -> subprocess.Popen:
        proc = self.sets.get(ranks)
        if proc is None or proc.poll() is not None:
            cmd = ["mpirun", "-n", str(ranks), sys.executable, os.path.abspath(__file__)]
            proc = subprocess.Popen(cmd, cwd=self.cwd, env=self.env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL, text=True, start_new_session=True)
            self.sets[ranks] = proc
        return proc

    def _stop(self, ranks: int) -> None:
        proc = self.sets.pop(ranks, None)
        if proc is not None and proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

    def close(self) -> None:
        """Ends the worker sets (their stdin closed: each returns from serve) and removes the captures' directory."""
        for ranks, proc in list(self.sets.items()):
            with contextlib.suppress(OSError):
                proc.stdin.close()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self._stop(ranks)
        self.sets.clear()
        shutil.rmtree(self.dir, ignore_errors=True)       # the runs' captured outputs (read and removed already)

    def run(self, args: Sequence[object], ranks: int, cwd: str, timeout: float) -> subprocess.CompletedProcess:
        """``python ARGS`` on ``ranks`` workers; the CompletedProcess mpirun would give (the ranks' outputs one
        after the other). subprocess.TimeoutExpired past ``timeout`` s (the workers are stopped)."""
        args = [str(a) for a in args]
        RUNS_HERE[1] += 1
        return self._request({"args": args}, ranks, cwd, timeout)[0]

    def cell_ranks(self, scene_and_options: Sequence[str], ranks: int, cwd: str, timeout: float) -> list[int]:
        """The rank of every cell of a scene (its file, then options) as the workers partition it."""
        proc, reply = self._request({"partition": [str(a) for a in scene_and_options]}, ranks, cwd, timeout)
        assert proc.returncode == 0, proc.stderr
        return reply["cell_ranks"]

    def _request(self, req: dict, ranks: int, cwd: str, timeout: float) -> tuple[subprocess.CompletedProcess, dict]:
        args = req.get("args", req.get("partition"))
        self.count += 1
        capture = os.path.join(self.dir, f"run{self.count}")
        proc = self._start(ranks)
        proc.stdin.write(json.dumps({**req, "cwd": cwd, "capture": capture}) + "\n")
        proc.stdin.flush()
        reply = self._answer(proc, timeout)
        timed_out = reply is None and proc.poll() is None
        if reply is None:
            self._stop(ranks)
        out = "".join(self._read(f"{capture}.{r}.out") for r in range(ranks))
        err = "".join(self._read(f"{capture}.{r}.err") for r in range(ranks))
        if timed_out:
            raise subprocess.TimeoutExpired(args, timeout, out, err)
        code = proc.returncode if reply is None else next((c for c in reply["codes"] if c != 0), 0)
        return subprocess.CompletedProcess(args, code, out, err), reply or {}

    def _answer(self, proc: subprocess.Popen, timeout: float) -> dict | None:
        """The workers' answer, or None if they ended (an abort: proc.returncode set) or did not answer within
        ``timeout`` s."""
        end = time.monotonic() + timeout
        with selectors.DefaultSelector() as sel:
            sel.register(proc.stdout, selectors.EVENT_READ)
            while time.monotonic() < end:
                if not sel.select(timeout=min(1.0, end - time.monotonic())):
                    continue
                line = proc.stdout.readline()
                if not line:
                    proc.wait()
                    return None
                if line.startswith(ANSWER):
                    return json.loads(line[len(ANSWER):])
        return None

    @staticmethod
    def _read(path: str) -> str:
        try:
            with open(path, errors="replace") as fh:
                text = fh.read()
        except FileNotFoundError:
            return ""
        os.remove(path)
        return text


if __name__ == "__main__":
    serve()
