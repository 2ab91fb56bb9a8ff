"""Running pfault on a scene with option overrides, for the tools that run a scene many times (calibration,
scenarios); what a run wrote is read with pfault.post.rundir.

Each run is a separate ``python -m pfault SCENE -pfault_output_dir DIR [-option value ...]`` (``mpirun -n N``
in front for N > 1 ranks) started from the working directory of the caller, so that the scene's relative
paths mean what they mean on the command line; its stdout and stderr go to ``DIR.log`` beside its output
directory. Runs are independent processes: ``run_many`` starts up to ``workers`` of them side by side.

This module does not import PETSc.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

_LIVE: set = set()                 # runs under way (run_many stops them all when its caller is interrupted)
_LIVE_LOCK = threading.Lock()
ERROR_PREFIXES = ("pfault: error:", "pfault: internal error:")


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
    log: str                # its stdout and stderr

    @property
    def ok(self) -> bool:
        return self.code == 0


def option_args(overrides: Mapping[str, str]) -> list[str]:
    """['-name', 'value', ...] of a mapping of option names (with or without the leading '-') to values."""
    args: list[str] = []
    for name, value in overrides.items():
        args += ["-" + name.lstrip("-"), str(value)]
    return args


def pfault_command(run: Run, python: str = sys.executable) -> list[str]:
    """The command line of a run: figures and GIS layers off unless asked, the overrides after the scene's own
    options."""
    args = [python, "-m", "pfault", run.scene, "-pfault_output_dir", run.output_dir,
            "-pfault_figures", "true" if run.figures else "false", "-pfault_gis", "true" if run.gis else "false",
            *option_args(run.overrides)]
    if run.ranks == 1:
        return args
    over = ["--oversubscribe"] if run.ranks > (os.cpu_count() or 1) else []
    return ["mpirun", "-n", str(run.ranks), *over, *args]


def run_environment(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """One BLAS thread per rank (runs side by side share the cores), Open MPI allowed as root."""
    env = dict(os.environ if base is None else base)
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", OMPI_MCA_btl_vader_single_copy_mechanism="none")
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def error_line(output: str) -> str | None:
    """The last 'pfault: error: ...' (or internal error) line of a run's output."""
    lines = [line.strip() for line in output.splitlines() if line.strip().startswith(ERROR_PREFIXES)]
    return lines[-1] if lines else None


def run_pfault(run: Run, cwd: str | None = None, env: Mapping[str, str] | None = None) -> RunResult:
    """Makes one run and waits for it; its output goes to ``<output_dir>.log``. A run past its timeout is
    killed with its ranks (its own process group), and so is a run whose caller is interrupted (run_many
    stops the runs of its other threads too)."""
    out = os.path.abspath(os.path.join(cwd or os.getcwd(), run.output_dir))
    os.makedirs(os.path.dirname(out), exist_ok=True)
    log = out.rstrip(os.sep) + ".log"
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.Popen(pfault_command(run), cwd=cwd, env=run_environment(env), stdout=fh,
                                stderr=subprocess.STDOUT, start_new_session=True)
        with _LIVE_LOCK:
            _LIVE.add(proc)
        try:
            code = proc.wait(timeout=run.timeout)
            timed_out = False
        except subprocess.TimeoutExpired:
            code, timed_out = _kill(proc), True
        except BaseException:
            _kill(proc)
            raise
        finally:
            with _LIVE_LOCK:
                _LIVE.discard(proc)
    wall = time.perf_counter() - t0
    with open(log, errors="replace") as fh:
        text = fh.read()
    error = None
    if timed_out:
        error = f"pfault: error: the run was stopped after {run.timeout:g} s (its timeout)"
    elif code != 0:
        error = error_line(text) or f"pfault exited {code} without an error line; see {log}"
    return RunResult(run, code, wall, error, log)


def _kill(proc):
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    return proc.wait()


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
        with _LIVE_LOCK:
            live = list(_LIVE)
        for proc in live:
            _kill(proc)
        raise
    finally:
        pool.shutdown(wait=True)


