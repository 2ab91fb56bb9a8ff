"""Running pfault (or a script) for the studies, the benchmarks and the tests: the environment Open MPI needs
here, the command line (plain python on one rank, mpirun on more), a run whose output is captured, and a run
logged to a file with its wall time, CPU time and load average, stopped at a timeout."""

from __future__ import annotations

import contextlib
import os
import platform
import resource
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHOWN_PYTHON = ".venv/bin/python"         # how a command shows the interpreter in reports
LOAD_POLL = 2.0                           # s between samples of the 1-minute load average during a run


def mpi_env(oversubscribe=False):
    """Environment for running pfault under Open MPI here: one BLAS thread per rank, Open MPI allowed as root,
    optionally more ranks than cores (the same settings as scripts/env.sh), and this checkout of pfault first
    on the import path."""
    env = dict(os.environ)
    # the subprocesses import this pfault (not another checkout an editable install may point to)
    env["PYTHONPATH"] = os.pathsep.join([REPO] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", OMPI_MCA_btl_vader_single_copy_mechanism="none")
    if oversubscribe:
        env["OMPI_MCA_rmaps_base_oversubscribe"] = "1"
    if os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def command(args, ranks=1):
    """``python ARGS`` on one rank; ``mpirun -n RANKS python ARGS`` on more, oversubscribed beyond the cores."""
    cmd = [sys.executable, *map(str, args)]
    if ranks == 1:
        return cmd
    over = ["--oversubscribe"] if ranks > (os.cpu_count() or 1) else []
    return ["mpirun", "-n", str(ranks), *over, *cmd]


def shown(cmd):
    """A command as typed from the repository root (for reports)."""
    text = " ".join(shlex.quote(str(a)) for a in cmd)
    return text.replace(sys.executable, SHOWN_PYTHON).replace(REPO + os.sep, "")


def run_captured(args, ranks=1, timeout=None, env=None):
    """Runs ``python ARGS`` from the repository root with its output captured; returns the CompletedProcess
    (subprocess.TimeoutExpired past timeout s)."""
    return subprocess.run(command(args, ranks), cwd=REPO, env=env or mpi_env(), capture_output=True, text=True,
                          timeout=timeout)


@dataclass
class Logged:
    """A run of run_logged."""
    code: int               # exit code (negative: killed by that signal)
    timed_out: bool         # stopped at the timeout
    wall: float             # s, end to end (MPI start-up, imports, output included)
    cpu: float              # CPU s of the process and its children (all ranks)
    loads: list             # 1-minute load average at the start and every LOAD_POLL s
    command: str            # as shown in reports
    log: str                # the file holding its stdout and stderr

    @property
    def load(self):
        """Mean 1-minute load average during the run."""
        return sum(self.loads) / len(self.loads)

    @property
    def output(self):
        with open(self.log) as fh:
            return fh.read()


def run_logged(args, ranks, log_path, timeout):
    """Runs ``python ARGS`` on RANKS ranks from the repository root, its stdout and stderr into log_path; the run
    (mpirun and its ranks: its own process group) is killed after timeout s, or when this process is stopped."""
    cmd = command(args, ranks)
    os.makedirs(os.path.dirname(os.path.abspath(log_path)), exist_ok=True)
    loads = [os.getloadavg()[0]]
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    timed_out = False
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, cwd=REPO, env=mpi_env(), stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            while True:
                try:
                    code = proc.wait(timeout=LOAD_POLL)
                    break
                except subprocess.TimeoutExpired:
                    loads.append(os.getloadavg()[0])
                    if time.perf_counter() - t0 > timeout:
                        timed_out = True
                        code = _kill(proc)
                        break
        except BaseException:
            _kill(proc)
            raise
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    return Logged(code, timed_out, wall, cpu, loads, shown(cmd), log_path)


def _kill(proc):
    """Kills a run of run_logged with its ranks; returns its exit code."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    return proc.wait()


def cpu_model():
    """The processor's name, for reports."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"
