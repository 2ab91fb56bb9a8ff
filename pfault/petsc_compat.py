"""The PETSc calls pfault needs that petsc4py 3.18 (Debian 12) does not bind, reached through ctypes here and
nowhere else. Each is used through petsc4py when the installed version has it.

- ``PetscOptionsLeftGet``: the options no PETSc object has read, which ``-options_left`` prints at the end of a
  run; pfault rejects them after the first solve, so that a misspelled solver option is an error, not a silent
  default (petsc4py has no binding in any version).
- ``SNESSetLagPreconditioner``: keeps a direct solver's factors across Newton iterations
  (``pfault.solver.policy.FactorReuse``; petsc4py binds it from 3.19 on).
- ``SNESConvergedDefault``: SNES's own convergence test, which a convergence test written in Python extends
  (``pfault.solver.policy.Settling``; petsc4py has no binding in any version).
- ``PCGetReusePreconditioner``: whether a PC keeps its preconditioner when its operator changes, which the margins'
  solve sets for itself and gives back (``pfault.solver.policy.StepSolver.solve_response``; petsc4py binds it from
  3.22 on).
"""

from __future__ import annotations

import ctypes
from typing import Any

_LIBPETSC: Any = None


def _library() -> Any:
    """The already loaded libpetsc shared object (Debian's or a pip build), or None."""
    global _LIBPETSC
    if _LIBPETSC is None:
        with open("/proc/self/maps") as fh:
            for line in fh:
                path = line.split()[-1]
                if "libpetsc" in path and ".so" in path:
                    _LIBPETSC = ctypes.CDLL(path)
                    break
    return _LIBPETSC


def options_left(PETSc: Any) -> list[str]:
    """Names of the options in PETSc's database that no object has read (as -options_left reports them)."""
    lib = _library()
    if lib is None:
        return []
    int_t = ctypes.c_int64 if PETSc.IntType().itemsize == 8 else ctypes.c_int32
    n = int_t(0)
    names = ctypes.POINTER(ctypes.c_char_p)()
    values = ctypes.POINTER(ctypes.c_char_p)()
    if lib.PetscOptionsLeftGet(None, ctypes.byref(n), ctypes.byref(names), ctypes.byref(values)) != 0:
        return []
    left = [names[i].decode() for i in range(n.value)]
    lib.PetscOptionsLeftRestore(None, ctypes.byref(n), ctypes.byref(names), ctypes.byref(values))
    return left


def set_lag_preconditioner(snes: Any, lag: int) -> None:
    """SNESSetLagPreconditioner(snes, lag): -1 keeps the preconditioner, -2 rebuilds it once, then keeps it."""
    if hasattr(snes, "setLagPreconditioner"):
        snes.setLagPreconditioner(lag)
        return
    lib = _library()
    lib.SNESSetLagPreconditioner.argtypes = [ctypes.c_void_p, ctypes.c_int]
    err = lib.SNESSetLagPreconditioner(ctypes.c_void_p(snes.handle), lag)
    if err:
        raise RuntimeError(f"SNESSetLagPreconditioner returned {err}")


def reuse_preconditioner(pc: Any) -> bool:
    """PCGetReusePreconditioner(pc): whether ``pc`` keeps its preconditioner when its operator changes."""
    if hasattr(pc, "getReusePreconditioner"):
        return bool(pc.getReusePreconditioner())
    lib = _library()
    flag = ctypes.c_int(0)      # PetscBool is a C enum
    lib.PCGetReusePreconditioner.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)]
    err = lib.PCGetReusePreconditioner(ctypes.c_void_p(pc.handle), ctypes.byref(flag))
    if err:
        raise RuntimeError(f"PCGetReusePreconditioner returned {err}")
    return bool(flag.value)


def converged_default(PETSc: Any, snes: Any, its: int, xnorm: float, ynorm: float, fnorm: float) -> int:
    """SNESConvergedDefault(snes, its, xnorm, ynorm, fnorm): SNES's default test (absolute, relative and step
    tolerances, divergence, function evaluations) of an iterate; returns its SNESConvergedReason."""
    lib = _library()
    int_t = ctypes.c_int64 if PETSc.IntType().itemsize == 8 else ctypes.c_int32
    real = ctypes.c_double
    lib.SNESConvergedDefault.argtypes = [ctypes.c_void_p, int_t, real, real, real, ctypes.POINTER(ctypes.c_int),
                                         ctypes.c_void_p]
    reason = ctypes.c_int(0)
    err = lib.SNESConvergedDefault(ctypes.c_void_p(snes.handle), its, xnorm, ynorm, fnorm, ctypes.byref(reason),
                                   None)
    if err:
        raise RuntimeError(f"SNESConvergedDefault returned {err}")
    return int(reason.value)
