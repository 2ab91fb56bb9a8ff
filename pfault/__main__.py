"""``python -m pfault SCENE.opts [-option value ...]``: runs a scene (a PETSc options file).

petsc4py.init() must see the options before PETSc is imported, so the scene file is turned into
``-options_file SCENE.opts`` ahead of the command-line options, which therefore override it.

Before that, the command line and the options files (the scene and those it includes with
``-options_file``) are read here as PETSc will read them, so that a stray argument, a binary or malformed
file or a missing included file is one line naming it, not a PETSc traceback. An option given twice in
the same file, or twice on the command line, is a warning naming the value used (the command line
overriding a file is the normal way to change a scene and says nothing).
"""

import os
import sys
from dataclasses import dataclass

from pfault.errors import EXIT_INPUT, EXIT_USAGE

USAGE = ("usage: mpirun -n N python -m pfault SCENE.opts [-option value ...]   (python -m pfault -help lists the "
         "options and exit codes)")
COMMAND_LINE = "the command line"


class ArgumentError(Exception):
    """One line, and the exit code it ends the run with."""

    def __init__(self, message, code):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Entry:
    name: str           # without the leading '-', lower case (PETSc's names are case-insensitive)
    value: object       # str or None
    source: str         # a file name or COMMAND_LINE
    line: int           # line in the file (0 on the command line)


def _first_rank():
    """True unless an MPI launcher says this process is not rank 0 (MPI is not started yet)."""
    for var in ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK"):
        if var in os.environ:
            return os.environ[var] == "0"
    return True


def _say(text):
    if _first_rank():
        sys.stderr.write(text + "\n")
        sys.stderr.flush()


def is_option_name(token):
    """PETSc's rule (PetscOptionsValidKey): '-' or '--' then a letter, and not a number such as -inf."""
    body = token[2:] if token.startswith("--") else token[1:]
    if not token.startswith("-") or not body[:1].isalpha():
        return False
    try:
        float(token)
    except ValueError:
        return True
    return False


def _name(token):
    return (token[2:] if token.startswith("--") else token[1:]).lower()


def read_options_file(path, included_by=()):
    """Entries of a PETSc options file, nested -options_file expanded in place (paths relative to the
    working directory, as PETSc reads them). Raises ArgumentError (exit 1) for what PETSc would reject."""
    if path in included_by:
        raise ArgumentError(f"{included_by[-1]}: -options_file {path} is already being read (the files "
                            "include each other); remove the loop", EXIT_INPUT)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise ArgumentError(f"options file {path}: cannot read it ({exc.strerror})", EXIT_INPUT) from None
    try:
        if b"\0" in data:
            raise UnicodeDecodeError("utf-8", data, 0, 1, "NUL byte")
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ArgumentError(f"{path}: not a text options file (binary content); give a PETSc options file "
                            "such as config/demo.opts", EXIT_INPUT) from None
    entries = []
    for number, line in enumerate(text.splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens or tokens[0] == "alias":
            continue
        where = f"{path} line {number}"
        if not is_option_name(tokens[0]):
            raise ArgumentError(f"{where}: '{tokens[0]}' is not an option name (one '-name value' per line, "
                                "comments after '#')", EXIT_INPUT)
        second = next((t for t in tokens[1:] if is_option_name(t)), None)
        if second:
            raise ArgumentError(f"{where}: two options on one line ({tokens[0]} ... {second}); give one per line",
                                EXIT_INPUT)
        if len(tokens) > 2:
            raise ArgumentError(f"{where}: {tokens[0]} has more than one value ('{' '.join(tokens[1:])}'); "
                                "lists are comma-separated without spaces", EXIT_INPUT)
        value = tokens[1] if len(tokens) == 2 else None
        entries += _entry_or_include(tokens[0], value, path, number, included_by)
    return entries


def _entry_or_include(token, value, source, line, included_by):
    name = _name(token)
    if name != "options_file":
        return [Entry(name, value, source, line)]
    where = f"{source} line {line}" if line else "on the command line"
    if value is None:
        raise ArgumentError(f"{where}: -options_file needs a file name", EXIT_INPUT)
    if not os.path.isfile(value):
        raise ArgumentError(f"{where}: -options_file {value}: no such file (paths are relative to the "
                            f"directory pfault runs in, {os.getcwd()})", EXIT_INPUT)
    return read_options_file(value, included_by + ((source,) if line else ()))


def read_command_line(tokens, scene):
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


def duplicate_warnings(entries):
    """One line per option given more than once in the same source, with the value PETSc will use (the
    last one, in the order files and command line are read)."""
    used = {e.name: e for e in entries}
    by_source = {}
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


def check_arguments(argv):
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


def main(argv=None):
    argv = list(sys.argv if argv is None else argv)
    wants_help = any(a in ("-help", "--help", "-h") for a in argv[1:])
    if wants_help and (len(argv) < 2 or is_option_name(argv[1])):
        from pfault.options import help_text
        print(USAGE)
        print(help_text())
        return 0
    try:
        scene, rest = check_arguments(argv)
    except ArgumentError as exc:
        _say(f"pfault: error: {exc}")
        return exc.code
    rest = ["-help" if a in ("--help", "-h") else a for a in rest]
    import petsc4py
    petsc4py.init([argv[0], "-options_file", scene] + rest)
    try:
        from petsc4py import PETSc  # noqa: F401  (PetscInitialize reads the options here)
    except Exception as exc:  # noqa: BLE001
        _say(f"pfault: error: PETSc could not start with the options of {scene} and the command line "
             f"({exc}; PETSc's message is above)")
        return EXIT_INPUT
    from pfault import cli
    return cli.main(scene, argv)


def run(argv=None):
    """main(), with Ctrl-C before the run's own handling of it (while PETSc and pfault are imported) one line
    and exit code 7 instead of a traceback."""
    try:
        return main(argv)
    except KeyboardInterrupt:
        from pfault.errors import Interrupted, as_pfault_error
        err = as_pfault_error(KeyboardInterrupt())
        _say(err.line())
        return Interrupted.exit_code


if __name__ == "__main__":
    sys.exit(run())
