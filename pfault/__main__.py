"""``python -m pfault SCENE.opts [-option value ...]``: runs a scene (a PETSc options file).

petsc4py.init() must see the options before PETSc is imported, so the scene file's options (its includes
expanded, each found relative to the file that includes it: pfault.optionsfile.petsc_arguments) go ahead of
the command-line options, which therefore override them.

Before that, the command line and the options files (the scene and those it includes with
``-options_file``) are read here as PETSc will read them, so that a stray argument, a binary or malformed
file or a missing included file is one line naming it, not a PETSc traceback. An option given twice in
the same file, or twice on the command line, is a warning naming the value used (the command line
overriding a file is the normal way to change a scene and says nothing).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from pfault.errors import EXIT_INPUT, EXIT_USAGE, Interrupted, as_pfault_error, install_stop_handlers
from pfault.optionsfile import (COMMAND_LINE, ArgumentError, Entry, _entry_or_include, is_option_name,
                                petsc_arguments, read_options_file, replace_database)

USAGE = ("usage: mpirun -n N python -m pfault SCENE.opts [-option value ...]   (python -m pfault -help lists the "
         "options and exit codes)")


LAUNCHER_RANK = ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK")     # the rank an MPI launcher gives a process


def _first_rank():
    """True unless an MPI launcher says this process is not rank 0 (MPI is not started yet)."""
    for var in LAUNCHER_RANK:
        if var in os.environ:
            return os.environ[var] == "0"
    return True


def _mpi_on_one_node():
    """Open MPI's start for a job whose ranks are all on this node (a singleton, or OMPI_COMM_WORLD_LOCAL_SIZE equal
    to OMPI_COMM_WORLD_SIZE): the ob1 messaging layer (shared memory) without probing the others first (cm and its
    PSM/OFI transports, UCX: 0.2 s of every rank's MPI_Init, 0.24-0.28 s against 0.03-0.07 s on 2 ranks; ob1 is
    what the probing chooses on a node without a high-speed network), and a singleton without the daemon (orted)
    Open MPI starts beside it for the dynamic process management pfault never uses (0.16 s of a small scene's
    1.36 s). A choice of the user's (OMPI_MCA_pml, --mca pml, a pml in an MCA parameter file) stays, and a job
    across nodes keeps Open MPI's own selection."""
    env = os.environ
    launched = any(var in env for var in LAUNCHER_RANK)
    if not launched:
        env.setdefault("OMPI_MCA_ess_singleton_isolated", "1")
    one_node = not launched or env.get("OMPI_COMM_WORLD_LOCAL_SIZE", "") == env.get("OMPI_COMM_WORLD_SIZE")
    if one_node and "OMPI_MCA_pml" not in env and not _pml_in_parameter_files():
        env["OMPI_MCA_pml"] = "ob1"


def _pml_in_parameter_files() -> bool:
    """Whether an Open MPI parameter file (the user's, the system's) chooses a pml (an exclusion, ``^ucx``, is not
    a choice)."""
    files = [os.path.expanduser("~/.openmpi/mca-params.conf"), "/etc/openmpi/openmpi-mca-params.conf"]
    if os.environ.get("OPAL_PREFIX"):
        files.append(os.path.join(os.environ["OPAL_PREFIX"], "etc", "openmpi-mca-params.conf"))
    for path in files:
        try:
            with open(path, encoding="utf-8", errors="replace") as fh:
                for line in fh:
                    key, _, value = line.split("#", 1)[0].partition("=")
                    if key.strip() == "pml" and value.strip() and not value.strip().startswith("^"):
                        return True
        except OSError:
            continue
    return False


def _say(text):
    if _first_rank():
        sys.stderr.write(text + "\n")
        sys.stderr.flush()


def read_command_line(tokens: Sequence[str], scene: str | None) -> list[Entry]:
    """Entries of the options after the scene file; a stray argument is a usage error."""
    entries, i = [], 0
    while i < len(tokens):
        token = tokens[i]
        if not is_option_name(token):
            previous = " ".join(tokens[max(0, i - 2):i])
            if scene is None and (token.endswith(".opts") or os.path.isfile(token)):
                raise ArgumentError(f"the scene file '{token}' must come first, before the options\n{USAGE}",
                                    EXIT_USAGE)
            if token.endswith(".opts") or os.path.isfile(token):
                raise ArgumentError(f"a second scene file '{token}' after {scene}: give one scene (a scene "
                                    "can include another with -options_file)", EXIT_USAGE)
            raise ArgumentError(f"unexpected argument '{token}'" + (f" after '{previous}'" if previous else "")
                                + ": an option takes one value (lists are comma-separated without spaces)",
                                EXIT_USAGE)
        value = tokens[i + 1] if i + 1 < len(tokens) and not is_option_name(tokens[i + 1]) else None
        entries += _entry_or_include(token, value, COMMAND_LINE, 0, ())
        i += 1 if value is None else 2
    return entries


def duplicate_warnings(entries: Sequence[Entry]) -> list[str]:
    """One line per option given more than once in the same source, with the value PETSc will use (the
    last one, in the order files and command line are read)."""
    used = {e.name: e for e in entries}
    by_source: dict[tuple[str, str], list[Entry]] = {}
    for e in entries:
        by_source.setdefault((e.source, e.name), []).append(e)
    lines = []
    for (source, name), group in by_source.items():
        if len(group) < 2:
            continue
        where = f"in {source} (lines {', '.join(str(e.line) for e in group)})" if source != COMMAND_LINE \
            else "on the command line"
        last = used[name]
        value = "no value" if last.value is None else f"'{last.value}'"
        origin = "" if last.source == source else f" from {last.source}"
        lines.append(f"pfault: warning: -{name} is given {len(group)} times {where}; the value used is "
                     f"{value}{origin}")
    return lines


def _scene_problem(scene):
    if not os.path.exists(scene):
        return f"scene file '{scene}' not found (give a PETSc options file such as config/demo.opts)"
    if not os.path.isfile(scene):
        return f"scene file '{scene}' is not a file (give a PETSc options file such as config/demo.opts)"
    return None


def check_arguments(argv: Sequence[str]) -> tuple[str, list[str]]:
    """(scene, rest) of a valid command line, or raises ArgumentError. Prints duplicate warnings."""
    rest = list(argv[1:])
    scene = rest.pop(0) if rest and not is_option_name(rest[0]) else None
    command_line = read_command_line(rest, scene)
    if scene is None:
        raise ArgumentError(f"no scene file given\n{USAGE}", EXIT_USAGE)
    problem = _scene_problem(scene)
    if problem:
        raise ArgumentError(problem, EXIT_USAGE)
    for line in duplicate_warnings(read_options_file(scene) + command_line):
        _say(line)
    return scene, rest


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv if argv is None else argv)
    wants_help = any(a in ("-help", "--help", "-h") for a in argv[1:])
    if wants_help and (len(argv) < 2 or is_option_name(argv[1])):
        from pfault.options import help_text      # imports PETSc: PETSc starts with no options here
        print(USAGE)
        print(help_text())
        return 0
    try:
        scene, rest = check_arguments(argv)
    except ArgumentError as exc:
        _say(f"pfault: error: {exc}")
        return exc.code
    rest = ["-help" if a in ("--help", "-h") else a for a in rest]
    if not start_petsc(argv[0], scene, petsc_arguments(scene, rest)):
        return EXIT_INPUT
    from pfault.cli import main as run_scene      # imports PETSc: after petsc4py.init
    return run_scene(scene, argv)


def start_petsc(program: str, scene: str, args: list[str]) -> bool:
    """Starts PETSc with ``args`` (the scene's options, then the command line's); False (the error said) if it
    cannot. In a process whose PETSc runs already (a driver running scenes one after another, the test suite)
    the options database is replaced by ``args`` instead, so that no option of an earlier run carries over;
    the options PETSc reads only when it starts or ends (-log_view, -malloc_debug, ...) do nothing there."""
    if "petsc4py.PETSc" in sys.modules:
        from petsc4py import PETSc
        replace_database(PETSc.Options(), args)
        return True
    import petsc4py
    petsc4py.init([program] + args)
    try:
        from petsc4py import PETSc  # noqa: F401  (PetscInitialize reads the options here)
    except Exception as exc:  # noqa: BLE001
        _say(f"pfault: error: PETSc could not start with the options of {scene} and the command line "
             f"({exc}; PETSc's message is above)")
        return False
    return True


def run(argv: Sequence[str] | None = None) -> int:
    """main(), with a stop signal before the run's own handling of it one line and exit code 7 instead of a
    traceback or a death by signal: SIGTERM, SIGINT (Ctrl-C) and SIGUSR1 raise StopSignal from here on
    (pfault.errors.stop_signal; the time loop installs its own handlers and puts these back after it)."""
    install_stop_handlers()
    _mpi_on_one_node()
    try:
        return main(argv)
    except KeyboardInterrupt as exc:
        _say(as_pfault_error(exc).line())
        return Interrupted.exit_code


if __name__ == "__main__":
    sys.exit(run())
