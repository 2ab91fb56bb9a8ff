"""SNES/KSP construction with code defaults that never overwrite what the user set."""

from __future__ import annotations

import os
from importlib import resources
from typing import TYPE_CHECKING

import numpy as np
from petsc4py import PETSc

from .. import optionsfile
from ..errors import InputError

if TYPE_CHECKING:
    from ..fields import DofMap
    from ..mesh.distributed import LocalMesh


def set_default(name: str, value: str) -> None:
    """Set an option only if the user did not (command line and options files win)."""
    opts = PETSc.Options()
    if not opts.hasName(name):
        opts.setValue(name, value)


def read_options_file(path: str) -> list[tuple[str, object]]:
    """(name, value) pairs of a PETSc options file, read strictly (pfault.optionsfile): a malformed solver file
    is an InputError naming the file and line."""
    try:
        return [(e.name, e.value) for e in optionsfile.read_options_file(path)]
    except optionsfile.ArgumentError as exc:
        raise InputError(str(exc)) from None


def find_solver_file(name: str, scene_file: str = "") -> str:
    """The options file of ``-pfault_solver NAME``: NAME itself when it is a file, else ``solver/NAME.opts``
    beside the scene (a user's own solver file), else pfault's own ``NAME.opts`` (package data in
    pfault/solver/options, found through importlib.resources wherever pfault is installed)."""
    if os.path.isfile(name):
        return name
    if scene_file:
        own = os.path.join(os.path.dirname(scene_file), "solver", name + ".opts")
        if os.path.isfile(own):
            return os.path.normpath(own)
    packaged = resources.files("pfault.solver").joinpath("options")
    if packaged.joinpath(name + ".opts").is_file():
        return str(packaged.joinpath(name + ".opts"))
    known = sorted(f.name.removesuffix(".opts") for f in packaged.iterdir() if f.name.endswith(".opts"))
    raise InputError(f"-pfault_solver {name}: not a file, not solver/{name}.opts beside the scene, not one of "
                     f"pfault's solvers ({', '.join(known)})")


def apply_solver_file(name: str, scene_file: str = "") -> str | None:
    """Options of a solver file, each set only where the user has not set it. A preconditioner the user
    chose (-pc_type, or -PREFIX_pc_type of a sub-solver such as -fieldsplit_displacement_pc_type) does not
    inherit the file's settings of the preconditioner it replaces: the file's options under that prefix that
    configure a preconditioner (pc_*, mg_*, the MUMPS options, a fieldsplit's sub-solvers) are dropped; its
    Krylov options stay (a Krylov method chosen alone keeps the file's preconditioner), except those of the
    file's own Krylov method (-ksp_gmres_restart where the user chose -ksp_type cg)."""
    if not name:
        return None
    path = find_solver_file(name, scene_file)
    opts = PETSc.Options()
    entries = read_options_file(path)
    chosen = [key[:-len("pc_type")] for key, _ in entries if key.endswith("pc_type") and opts.hasName(key)]
    if opts.hasName("pc_type"):
        chosen.append("")
    krylov = [key[:-len("ksp_type")] for key, _ in entries if key.endswith("ksp_type") and opts.hasName(key)]
    if opts.hasName("ksp_type"):
        krylov.append("")
    for key, value in entries:
        if any(key.startswith(p) and key[len(p):].startswith(_PC_KEYS) for p in chosen):
            continue
        if any(key.startswith(p) and key[len(p):].startswith(_KSP_METHOD_KEYS) for p in krylov):
            continue
        if not opts.hasName(key):
            opts.setValue(key, "" if value is None else value)
    return path


_PC_KEYS = ("pc_", "mat_mumps", "mg_", "fieldsplit_", "sub_")
# options of one Krylov method (KSPSetFromOptions_<type>): meaningless under another -ksp_type
_KSP_METHOD_KEYS = tuple(f"ksp_{m}_" for m in ("gmres", "fgmres", "lgmres", "dgmres", "pgmres", "gcr", "chebyshev",
                                                "richardson", "bcgsl", "fcg", "pipefcg", "cg", "minres", "tfqmr"))


def is_direct() -> bool:
    """The options ask for a direct factorisation as the preconditioner (-pc_type lu or cholesky)."""
    return PETSc.Options().getString("pc_type", "") in ("lu", "cholesky")


def mumps_factors_on_ranks() -> bool:
    """The direct factorisation is MUMPS's on more than one rank."""
    opts = PETSc.Options()
    return PETSc.COMM_WORLD.getSize() > 1 and opts.getString("pc_factor_mat_solver_type", "mumps") == "mumps"


LINE_SEARCH = "bt"      # Newton's line search where a term's law needs one (SoilTerm.full_newton_steps)


def apply_solver_defaults(linear: bool = False, full_steps: bool = True) -> None:
    """Code defaults, each only where the user is silent. A linear scene (no fault) needs one linear solve per
    step: SNES type ksponly. A fault scene runs Newton (newtonls) on the semismooth residual with full steps, its
    step-size test off (-snes_stol 0: the unknowns mix metres and pascals, so a relative step size means nothing),
    its absolute tolerance set per step from the load unless given (pfault.solver.policy.StepSolver.load_tolerance).
    A direct factorisation is applied once per linear solve (preonly)."""
    opts = PETSc.Options()
    if linear:
        set_default("snes_type", "ksponly")
        set_default("snes_atol", "1e-12")
    else:
        set_default("snes_stol", "0")
        # Full semismooth Newton steps (paper-size Wuxi: 23 iterations over 10 steps). The law decides each face's
        # branch from t + c g with c <= E/h, about the stiffness of the cells around the face, so a step that
        # puts a face on the wrong side of its stick/slip or open/closed switch is undone by the next one;
        # backtracking on |F| mostly costs more iterations (fissure box at h/2, first year: 11 instead of 8; basin
        # fault, 10 steps: 48 instead of 46; the two blocks at 8 x 4 x 4 one fewer, 6 instead of 7). Penalty
        # faces take the same rows on their jump less the penalty's compliance (a perturbed Lagrangian), with
        # the same c: their iterations do not depend on k and are the Lagrange faces' (k = 1e2, 1e4, 1e6 E/h:
        # 8 with full steps, 11 backtracking; studies/penalty_linesearch.py). Backtracking was their default
        # while their traction was the return map of the jump with k itself (full steps 2-cycled there).
        set_default("snes_linesearch_type", "basic" if full_steps else LINE_SEARCH)
    if not opts.hasName("pc_type"):
        set_default("pc_type", "lu")
        set_default("pc_factor_mat_solver_type", "mumps")
    if is_direct() and not opts.hasName("ksp_type"):
        if linear:
            set_default("ksp_type", "preonly")
        else:
            # Flexible GMRES on the factorised Jacobian: one iteration after a factorisation, a few while its
            # factors are kept (pfault.solver.policy.FactorReuse: while few faces' states changed since). Keeping them
            # for a fixed number of Newton iterations whatever the states (-snes_lag_preconditioner 3) was
            # slower: calibrated Queretaro 216 s against 98 s, 160-320 triangular solves per step at 0.14 s each.
            # FGMRES keeps the preconditioned directions, so it applies the factors once per iteration; GMRES
            # (left-preconditioned) applies them once more to the initial residual: calibrated Queretaro 46
            # triangular solves instead of 89 (0.1 s each) for the same 36 Newton iterations
            set_default("ksp_type", "fgmres")
            set_default("ksp_rtol", "1e-8")
    if not linear and is_direct() and mumps_factors_on_ranks():
        # MUMPS orders the matrix it gathered from the ranks. Its automatic choice here (PORD) gives the same
        # matrix another ordering when the ranks' messages arrive in another order: Wuxi on a coarse mesh,
        # 2 ranks, 12 runs side by side on the 2 cores, three orderings of 777, 790 and 901 Mflop. The factor
        # reuse decides from the factors' cost (pfault.solver.policy.FactorReuse), so the Newton iterations'
        # linear solves and the answer followed the machine's load (1.4e-4 of a dataset apart). AMF orders the
        # same gathered matrix the same way however it arrives (804 Mflop in each of 24 such runs): the runs
        # of a scene decide and answer alike. Its factors cost more flops than PORD's (Wuxi, 41,742 unknowns,
        # 8.1 against 6.9 Gflop; calibrated Queretaro, 35,190: 5.4 against 4.2), which the runs' wall time does
        # not show at the sizes MUMPS is chosen for (pfault.solver.choice; three pairs side by side: Wuxi 8.0-9.3 s
        # against 8.9-10.0 s with PORD, Queretaro 10.7-11.3 s against 10.4-11.8 s). One rank keeps MUMPS's choice.
        set_default("mat_mumps_icntl_7", "2")
    set_default("snes_rtol", "1e-10")
    set_default("snes_max_it", "50")


def rigid_body_modes(mesh: LocalMesh, dofmap: DofMap, dm: PETSc.DM) -> PETSc.NullSpace:
    """Orthonormal rigid-body modes of the displacement field (zero on multiplier dofs) as a NullSpace."""
    x = mesh.coords
    vecs = []
    n_local = dofmap.n_local
    for mode in range(6):
        loc = np.zeros(n_local)
        vals = np.zeros((len(x), 3))
        if mode < 3:
            vals[:, mode] = 1.0
        else:
            a, b = [(0, 1), (1, 2), (2, 0)][mode - 3]
            vals[:, a] = -x[:, b]
            vals[:, b] = x[:, a]
        for side in range(dofmap.max_sides):
            sel = dofmap.vert_sides > side
            loc[dofmap.vertex_dofs(side)[sel]] = vals[sel]
        lv = dm.getLocalVec()
        lv.setArray(loc)
        g = dm.createGlobalVec()
        dm.localToGlobal(lv, g, addv=PETSc.InsertMode.INSERT_VALUES)
        dm.restoreLocalVec(lv)
        vecs.append(g)
    # modified Gram-Schmidt
    for i, v in enumerate(vecs):
        for w in vecs[:i]:
            v.axpy(-v.dot(w), w)
        v.normalize()
    ns = PETSc.NullSpace().create(vectors=vecs, comm=dm.getComm())
    for v in vecs:
        v.destroy()
    return ns
