"""How a run fails: one line, a documented exit code, and every rank ends.

Exit codes (also in pfault/cli.py and README.md)::

    0 done                      3 a step did not converge    6 internal error (a bug)
    1 bad input                 4 output cannot be written   7 interrupted (stopped after a step on
    2 usage                     5 out of memory                SIGTERM, SIGINT or SIGUSR1)

Errors that depend only on the options are raised by every rank together. Work done on one rank (the
serial mesh, output) runs through ``run_on_root``, which shares any exception it raises with every rank;
work every rank does together (output written in parallel) through ``run_on_all``.
What is left, an exception on some ranks only, is settled by ``RunGuard.settle``: if every rank reaches
it within a few seconds the ranks end together; otherwise the failing rank prints its line and aborts
the MPI job with the exit code (the others are waiting in a collective call and cannot be reached).

This module does not import PETSc: ``python -m pfault`` uses it before PETSc is initialised.
"""

from __future__ import annotations

import errno
import signal
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

EXIT_OK = 0
EXIT_INPUT = 1
EXIT_USAGE = 2
EXIT_NOT_CONVERGED = 3
EXIT_OUTPUT = 4
EXIT_MEMORY = 5
EXIT_INTERNAL = 6
EXIT_INTERRUPTED = 7

# what each code means, for -help and README.md (pfault.cli has the longer version)
EXIT_CODES = (
    (EXIT_OK, "done"),
    (EXIT_INPUT, "bad input: an option, the scene file or a mesh file"),
    (EXIT_USAGE, "usage: no scene file, a missing one, stray arguments"),
    (EXIT_NOT_CONVERGED, "a step did not converge, the groundwater-flow solve or the geostatic gravity solve failed"),
    (EXIT_OUTPUT, "the output cannot be written (not writable, a file in the way, the disk full)"),
    (EXIT_MEMORY, "out of memory"),
    (EXIT_INTERNAL, "internal error (a bug; its traceback comes before the line)"),
    (EXIT_INTERRUPTED, "interrupted: SIGTERM, SIGINT or SIGUSR1 stopped the run after a step "
                       "(-pfault_restart continues it)"),
)


def exit_code_table() -> str:
    return "\n".join(["Exit codes (the same on every rank; mpirun returns them):"]
                     + [f"  {code}  {text}" for code, text in EXIT_CODES])


PETSC_ERR_MEM = 55           # PETSc's error code for a failed allocation
SETTLE_SECONDS = 3.0         # how long a failing rank waits for the others before it aborts the job
SHARE_SECONDS = 60.0         # how long a rank that failed in work done by all waits for the others to finish it


class PfaultError(Exception):
    """An error that ends the run with ``exit_code``; its text is one line naming the option or file and
    the fix. ``detail`` holds a traceback worth printing (internal errors only)."""
    exit_code = EXIT_INTERNAL
    kind = "error"

    def __init__(self, message: str, detail: str | None = None) -> None:
        super().__init__(message)
        self.detail = detail

    def line(self, rank: int | None = None) -> str:
        """The line printed for it; ``rank`` when only that rank failed."""
        where = "" if rank is None else f" on rank {rank} (the other ranks are stopped)"
        return f"pfault: {self.kind}{where}: {self}"


class InputError(PfaultError):
    """A problem with user input: an option, a file or a value."""
    exit_code = EXIT_INPUT


class OutputError(PfaultError):
    """The output directory cannot be created or written, or its disk is full."""
    exit_code = EXIT_OUTPUT


class OutOfMemory(PfaultError):
    exit_code = EXIT_MEMORY


class StepNotConverged(PfaultError):
    """A solve failed in a way that ends the run (the groundwater-flow KSP, the geostatic gravity solve): exit
    code 3."""
    exit_code = EXIT_NOT_CONVERGED


class InternalError(PfaultError):
    exit_code = EXIT_INTERNAL
    kind = "internal error"


class Interrupted(PfaultError):
    """Ctrl-C (SIGINT, Python's KeyboardInterrupt) or SIGTERM / SIGUSR1 (StopSignal) outside the time loop,
    which has its own handlers (pfault.interrupt): the run stops where it is."""
    exit_code = EXIT_INTERRUPTED
    kind = "stopped"


class StopSignal(KeyboardInterrupt):
    """SIGTERM, SIGINT or SIGUSR1 outside the time loop, raised by the handler ``pfault.__main__`` installs at
    start-up (``stop_signal``; without it the signal's default action would end the process with no message and no
    exit code of ours)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1)
_stops_raised: list[str] = []       # the stop signals stop_signal raised in this process


def stop_signal(signum: int, frame: Any) -> None:
    """The start-up handler of the stop signals: raises StopSignal, and records it, so that code which swallows
    the exception with a bare ``except:`` cannot make the run go on as if no signal had come: Debian's h5py
    imports its MPI build under an MPI launcher and, on any exception, its serial build instead (a signal then
    is lost and the rank writes with serial HDF5). ``raise_swallowed_stop`` raises it again where the time loop
    starts (pfault.interrupt.StopRequest)."""
    name = signal.Signals(signum).name
    _stops_raised.append(name)
    raise StopSignal(name)


def install_stop_handlers() -> None:
    """``stop_signal`` for SIGTERM, SIGINT and SIGUSR1 (SIGUSR1 last: once it is caught, all are). SIGINT too:
    with Python's own handler (KeyboardInterrupt) a Ctrl-C at some moments of the start-up printed the one line and
    then ended the process by SIGINT instead of exit code 7 (3 of 16 sends 0.40-0.70 s into the start-up of a
    30x30x30-cell box; none of 16 with this handler)."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, stop_signal)


def raise_swallowed_stop() -> None:
    """StopSignal again for a stop signal ``stop_signal`` raised in this process and something swallowed (the
    process would have ended otherwise); the record is cleared."""
    if _stops_raised:
        name = _stops_raised[-1]
        _stops_raised.clear()
        raise StopSignal(name)


_KINDS = {cls.__name__: cls for cls in (PfaultError, InputError, OutputError, OutOfMemory, StepNotConverged,
                                        InternalError, Interrupted)}


def as_pfault_error(exc: BaseException) -> PfaultError:
    """The PfaultError an exception ends the run with (out of memory, a full disk and bugs included)."""
    if isinstance(exc, PfaultError):
        return exc
    if isinstance(exc, KeyboardInterrupt):
        return Interrupted(f"{getattr(exc, 'name', 'SIGINT')} outside the time loop (start-up, meshing, setup, "
                           "or the figures at the end): "
                           "the run stopped at once; every step it completed is on disk")
    if isinstance(exc, MemoryError):
        return OutOfMemory(f"out of memory ({exc or 'an allocation failed'}); use a smaller mesh "
                           "(-pfault_box_cells, -pfault_mesh_size_factor) or more nodes")
    if type(exc).__module__.startswith("petsc4py") and getattr(exc, "ierr", None) == PETSC_ERR_MEM:
        return OutOfMemory("out of memory (PETSc could not allocate); use a smaller mesh (-pfault_box_cells, "
                           "-pfault_mesh_size_factor), another solver (-pfault_solver gamg) or more nodes")
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        where = f" {exc.filename}" if exc.filename else ""
        return OutputError(f"cannot write{where}: {exc.strerror or exc}; free space on that disk or choose "
                           "another -pfault_output_dir")
    detail = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    text = " ".join(str(exc).split()) or "(no message)"
    return InternalError(f"{type(exc).__name__}: {text} (a bug: please report it with the command line and "
                         "the traceback above)", detail=detail)


def _mpi(comm):
    return comm.tompi4py() if hasattr(comm, "tompi4py") else comm


def _pack(err):
    return type(err).__name__, str(err), err.detail


def _unpack(packed):
    kind, message, detail = packed
    return _KINDS[kind](message, detail=detail)


def collective_check(comm: Any, message: str | None) -> None:
    """Raise InputError on every rank if any rank reports a problem.

    ``message`` is this rank's verdict: None when fine, otherwise a one-line text. The first
    non-empty message (lowest rank) is raised everywhere, so no rank is left waiting.
    """
    messages = _mpi(comm).allgather(message)
    for m in messages:
        if m:
            raise InputError(m)


def run_on_root(comm: Any, func: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Run ``func`` on rank 0 only and share the exception it raises, if any, with every rank.

    Returns func's result on rank 0 and None elsewhere. Any exception on rank 0 (an InputError, a full
    disk, a failed allocation, a bug) is raised on all ranks as the same PfaultError.
    """
    mpicomm = _mpi(comm)
    result, packed = None, None
    if mpicomm.rank == 0:
        try:
            result = func(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001  (every exception is shared, then raised again)
            packed = _pack(as_pfault_error(exc))
    if mpicomm.size > 1:
        packed = mpicomm.bcast(packed, root=0)
    if packed is not None:
        raise _unpack(packed)
    return result


def run_on_all(comm: Any, func: Callable[..., Any], *args: Any, wait: float = SHARE_SECONDS) -> Any:
    """Run ``func`` on every rank and raise an exception any rank raised on every rank (the lowest failing
    rank's, as the same PfaultError); returns func's result. For work all ranks do together (output written
    in parallel), between collective calls: every rank gets here after its part.

    A rank whose func raised waits at most ``wait`` seconds for the others to get here: when they do not
    (they are stuck in a collective call it left), it raises alone and ``RunGuard.settle`` aborts the job."""
    from mpi4py import MPI
    mpicomm = _mpi(comm)
    result, packed, error = None, None, None
    try:
        result = func(*args)
    except Exception as exc:  # noqa: BLE001  (every exception is shared, then raised again)
        error = exc
        packed = _pack(as_pfault_error(exc))
    if mpicomm.size == 1:
        if error is not None:
            raise _unpack(packed)
        return result
    failed = np.array([error is not None], dtype=np.int32)
    any_failed = np.zeros(1, dtype=np.int32)
    request = mpicomm.Iallreduce(failed, any_failed, op=MPI.MAX)
    if error is None:
        request.Wait()
    else:
        deadline = time.monotonic() + wait
        while not request.Test():
            if time.monotonic() > deadline:
                raise error
            time.sleep(0.01)
    if any_failed[0]:
        raise _unpack(next(p for p in mpicomm.allgather(packed) if p is not None))
    return result


def warn(comm: Any, text: str) -> str:
    """Print the warning ``text`` once, on rank 0, as the line ``pfault: warning: text``; returns the line
    (summary.json keeps a run's warnings). Called by every rank with the same text."""
    line = f"pfault: warning: {text}"
    if _mpi(comm).rank == 0:
        write_line(line)
    return line


def write_line(text: str) -> None:
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


class RunGuard:
    """Ends a failed run on every rank. Created by every rank at the start of a run (it duplicates the
    communicator, so its barrier cannot be confused with a collective call the others are waiting in)."""

    def __init__(self, comm: Any) -> None:
        self.comm = _mpi(comm).Dup()

    def settle(self, exc: BaseException, wait: float = SETTLE_SECONDS,
               last_words: Callable[[str, int], object] | None = None) -> int:
        """Called by a rank with an exception. Returns the exit code when every rank failed together (rank
        0 prints the line); otherwise prints this rank's line, calls ``last_words(line, exit code)`` (what
        this rank alone can still record: how the run ended, in summary.json) and aborts the MPI
        job with the code."""
        err = as_pfault_error(exc)
        comm = self.comm
        if comm.size == 1:
            self._print([_pack(err)])
            return err.exit_code
        request = comm.Ibarrier()
        deadline = time.monotonic() + wait
        while not request.Test():
            if time.monotonic() > deadline:
                self._print([_pack(err)], rank=comm.rank)
                if last_words is not None:
                    try:
                        last_words(err.line(comm.rank), err.exit_code)
                    except Exception:  # noqa: BLE001  (best effort: the job ends anyway)
                        pass
                from mpi4py import MPI
                MPI.COMM_WORLD.Abort(err.exit_code)
            time.sleep(0.01)
        errors = comm.gather(_pack(err), root=0)
        if comm.rank == 0:
            self._print(errors)
        return comm.bcast(_unpack(errors[0]).exit_code if comm.rank == 0 else None, root=0)

    @staticmethod
    def _print(packed_errors, rank=None):
        """One line per distinct error (ranks that failed together usually share one), with the
        traceback of an internal error before it."""
        seen = set()
        for packed in packed_errors:
            err = _unpack(packed)
            if err.line() in seen:
                continue
            seen.add(err.line())
            if err.detail:
                sys.stderr.write(err.detail)
            write_line(err.line(rank))

    def free(self) -> None:
        self.comm.Free()
