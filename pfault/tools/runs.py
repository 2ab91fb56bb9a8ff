"""Running pfault processes: the one runner of the calibration, the scenarios, the studies, the benchmarks and the
tests (what a run wrote is read with pfault.post.rundir).

A run is ``python -m pfault SCENE -pfault_output_dir DIR [-option value ...]`` (or any ``python ARGS``), with
``mpirun -n N`` in front on N > 1 ranks (``--oversubscribe`` past the cores), started from ``cwd`` (the caller's
working directory by default, so that a scene's relative paths mean what they mean on the command line) in
``environment()``: one BLAS thread per rank (runs side by side share the cores), Open MPI allowed as root, and,
from a checkout, this pfault first on the child's import path (not another checkout an editable install points to).

Every run is its own process group: a run stopped at its timeout, or whose caller is interrupted, is killed with
its ranks. Three ways to wait for one:

- ``run_captured``: its stdout and stderr returned (the tests);
- ``run_logged``: its output in a log file, with its wall time, CPU time and the machine's load (the studies and
  the benchmarks);
- ``run_pfault`` / ``run_many``: a scene with option overrides, its output in ``DIR.log``, up to ``workers`` side
  by side (the calibration, the scenarios, PEST's model command).

This module does not import PETSc.
"""

from __future__ import annotations

import contextlib
import os
import platform
import resource
import shlex
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import pfault

ERROR_PREFIXES = ("pfault: error:", "pfault: internal error:")
LOAD_POLL = 2.0                    # s between samples of the 1-minute load average during a logged run
SOURCE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(pfault.__file__)))   # where this pfault lies
SHOWN_PYTHON = ".venv/bin/python"  # how a command shows the interpreter in reports
# what an MPI launcher, or MPI started in this process, puts in the environment: a run is a new MPI job and must
# not see it (an mpirun that inherits a started MPI's PMIx server ends at once with exit code 1, saying nothing)
LAUNCH_CONTEXT = ("PMIX_", "PMI_", "OMPI_COMM_WORLD_", "OMPI_MCA_ess", "OMPI_MCA_pmix", "OMPI_MCA_orte_",
                  "OMPI_APP_CTX_", "OMPI_COMMAND", "OMPI_FILE_LOCATION", "ORTE_", "PRTE_", "HYDRA_")
_LIVE: set = set()                 # runs under way (stopped when their caller is interrupted)
_LIVE_LOCK = threading.Lock()


def environment(base: Mapping[str, str] | None = None, oversubscribe: bool = False) -> dict[str, str]:
    """The environment of a run: ``base`` (this process's by default) without an MPI launcher's context
    (LAUNCH_CONTEXT), with one BLAS thread per rank, Open MPI allowed as root and quiet about the shared-memory
    copy, optionally more ranks than cores, and (from a checkout) this pfault first on the import path."""
    env = {k: v for k, v in (os.environ if base is None else base).items() if not k.startswith(LAUNCH_CONTEXT)}
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", OMPI_MCA_btl_vader_single_copy_mechanism="none")
    if os.path.basename(SOURCE_ROOT) not in ("site-packages", "dist-packages"):     # a checkout, not installed
        paths = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p and p != SOURCE_ROOT]
        env["PYTHONPATH"] = os.pathsep.join([SOURCE_ROOT, *paths])
    if oversubscribe:
        env["OMPI_MCA_rmaps_base_oversubscribe"] = "1"
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def command(args: Sequence[object], ranks: int = 1, python: str = sys.executable) -> list[str]:
    """``python ARGS`` on one rank; ``mpirun -n RANKS python ARGS`` on more, oversubscribed beyond the cores."""
    cmd = [python, *map(str, args)]
    if ranks == 1:
        return cmd
    over = ["--oversubscribe"] if ranks > (os.cpu_count() or 1) else []
    return ["mpirun", "-n", str(ranks), *over, *cmd]


def shown(cmd: Sequence[object], root: str = SOURCE_ROOT) -> str:
    """A command as typed from the checkout's root (for reports)."""
    text = " ".join(shlex.quote(str(a)) for a in cmd)
    return text.replace(sys.executable, SHOWN_PYTHON).replace(root + os.sep, "")


def option_args(overrides: Mapping[str, object]) -> list[str]:
    """['-name', 'value', ...] of a mapping of option names (with or without the leading '-') to values."""
    args: list[str] = []
    for name, value in overrides.items():
        args += ["-" + name.lstrip("-"), str(value)]
    return args


def error_line(output: str) -> str | None:
    """The last 'pfault: error: ...' (or internal error) line of a run's output."""
    lines = [line.strip() for line in output.splitlines() if line.strip().startswith(ERROR_PREFIXES)]
    return lines[-1] if lines else None


# ------------------------------------------------------------------------------------------------------
# starting and stopping a process group
# ------------------------------------------------------------------------------------------------------
def _start(cmd: list[str], cwd: str | None, env: Mapping[str, str] | None, **streams: object) -> subprocess.Popen:
    proc = subprocess.Popen(cmd, cwd=cwd, env=dict(env) if env is not None else environment(),
                            start_new_session=True, **streams)
    with _LIVE_LOCK:
        _LIVE.add(proc)
    return proc


def _done(proc: subprocess.Popen) -> None:
    with _LIVE_LOCK:
        _LIVE.discard(proc)


def _kill(proc: subprocess.Popen) -> int:
    """Kills a run with its ranks (its process group); returns its exit code."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    return proc.wait()


def stop_all() -> None:
    """Kills every run under way (those of other threads too)."""
    with _LIVE_LOCK:
        live = list(_LIVE)
    for proc in live:
        _kill(proc)


def run_captured(args: Sequence[object], ranks: int = 1, cwd: str | None = None,
                 env: Mapping[str, str] | None = None, timeout: float | None = None,
                 stdin: str | None = None) -> subprocess.CompletedProcess:
    """Runs ``python ARGS`` with its output captured (``stdin`` its input, if given) and waits for it; the
    CompletedProcess. Past ``timeout`` s the run is killed with its ranks and subprocess.TimeoutExpired raised,
    with the output so far."""
    cmd = command(args, ranks)
    proc = _start(cmd, cwd, env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                  stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL)
    try:
        out, err = proc.communicate(input=stdin, timeout=timeout)
    except subprocess.TimeoutExpired:
        _kill(proc)
        out, err = proc.communicate()
        raise subprocess.TimeoutExpired(cmd, timeout, out, err) from None
    except BaseException:
        _kill(proc)
        raise
    finally:
        _done(proc)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


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
    def load(self) -> float:
        """Mean 1-minute load average during the run."""
        return sum(self.loads) / len(self.loads)

    @property
    def output(self) -> str:
        with open(self.log, errors="replace") as fh:
            return fh.read()


def run_logged(args: Sequence[object], ranks: int, log_path: str, timeout: float | None = None,
               cwd: str | None = None, env: Mapping[str, str] | None = None) -> Logged:
    """Runs ``python ARGS`` on RANKS ranks, its stdout and stderr into log_path; the run is killed with its
    ranks after timeout s, or when this process is stopped."""
    cmd = command(args, ranks)
    os.makedirs(os.path.dirname(os.path.abspath(log_path)), exist_ok=True)
    loads = [os.getloadavg()[0]]
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    timed_out = False
    with open(log_path, "w") as log:
        proc = _start(cmd, cwd, env, stdout=log, stderr=subprocess.STDOUT)
        try:
            while True:
                try:
                    code = proc.wait(timeout=LOAD_POLL)
                    break
                except subprocess.TimeoutExpired:
                    loads.append(os.getloadavg()[0])
                    if timeout is not None and time.perf_counter() - t0 > timeout:
                        timed_out, code = True, _kill(proc)
                        break
        except BaseException:
            _kill(proc)
            raise
        finally:
            _done(proc)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    return Logged(code, timed_out, wall, cpu, loads, shown(cmd), log_path)


# ------------------------------------------------------------------------------------------------------
# scenes with option overrides, side by side
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Run:
    """One run to make: the scene, where it writes, and the options that override the scene's."""
    scene: str
    output_dir: str
    overrides: Mapping[str, str] = field(default_factory=dict)   # option name (with or without '-') -> value
    ranks: int = 1
    figures: bool = False
    timeout: float | None = None                                  # s; the run is killed past it
    gis: bool = False                                             # -pfault_gis: the GIS layers of a scene with a CRS


@dataclass(frozen=True)
class RunResult:
    run: Run
    code: int               # pfault's exit code (negative: killed by that signal)
    wall: float             # s, end to end
    error: str | None       # the run's one-line error ('pfault: error: ...'), None when it exited 0
    log: str                # the file holding its stdout and stderr

    @property
    def ok(self) -> bool:
        return self.code == 0


def pfault_args(run: Run) -> list[str]:
    """``-m pfault ...`` of a run: figures and GIS layers off unless asked, the overrides after the scene's own
    options."""
    return ["-m", "pfault", run.scene, "-pfault_output_dir", run.output_dir,
            "-pfault_figures", "true" if run.figures else "false", "-pfault_gis", "true" if run.gis else "false",
            *option_args(run.overrides)]


def run_pfault(run: Run, cwd: str | None = None, env: Mapping[str, str] | None = None) -> RunResult:
    """Makes one run and waits for it; its output goes to ``<output_dir>.log``. A run past its timeout is
    killed with its ranks, and so is a run whose caller is interrupted (run_many stops the runs of its other
    threads too)."""
    out = os.path.abspath(os.path.join(cwd or os.getcwd(), run.output_dir))
    os.makedirs(os.path.dirname(out), exist_ok=True)
    log = out.rstrip(os.sep) + ".log"
    done = run_logged(pfault_args(run), run.ranks, log, run.timeout, cwd, environment(env))
    error = None
    if done.timed_out:
        error = f"pfault: error: the run was stopped after {run.timeout:g} s (its timeout)"
    elif done.code != 0:
        error = error_line(done.output) or f"pfault exited {done.code} without an error line; see {log}"
    return RunResult(run, done.code, done.wall, error, log)


def run_many(runs: Iterable[Run], workers: int = 1, cwd: str | None = None,
             env: Mapping[str, str] | None = None) -> list[RunResult]:
    """Makes the runs, up to ``workers`` at a time; results in the order of ``runs``."""
    runs = list(runs)
    if workers <= 1 or len(runs) <= 1:
        return [run_pfault(r, cwd, env) for r in runs]
    pool = ThreadPoolExecutor(max_workers=min(workers, len(runs)))
    try:
        return list(pool.map(lambda r: run_pfault(r, cwd, env), runs))
    except BaseException:            # Ctrl-C reaches this thread only: stop the runs (own sessions) here
        pool.shutdown(wait=False, cancel_futures=True)
        stop_all()
        raise
    finally:
        pool.shutdown(wait=True)


def cpu_model() -> str:
    """The processor's name, for reports of timed runs."""
    with contextlib.suppress(OSError):
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown CPU"
