"""PETSc options files read as PETSc reads them, strictly: a binary or malformed file, two options on a line,
a missing or looping nested ``-options_file`` is an ArgumentError naming the file and line (exit code 1).
Used before PETSc starts (pfault.__main__: the scene and its includes) and for solver files
(pfault.solver.setup).

One difference from PETSc: a file included from another (``-options_file`` inside a file) is found relative
to the directory of the file that includes it, so that a scene runs from any directory; an absolute path is
used as it is, and ``-options_file`` on the command line is relative to the working directory. PETSc itself
would look in the working directory, so pfault hands PETSc the files' options expanded (``petsc_arguments``)
rather than the files."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from pfault.errors import EXIT_INPUT
from pfault.paths import file_problem

COMMAND_LINE = "the command line"


class ArgumentError(Exception):
    """One line, and the exit code it ends the run with."""

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Entry:
    name: str           # without the leading '-', lower case (PETSc's names are case-insensitive)
    value: object       # str or None
    source: str         # a file name or COMMAND_LINE
    line: int           # line in the file (0 on the command line)


def is_option_name(token: str) -> bool:
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


def read_options_file(path: str, included_by: tuple[str, ...] = ()) -> list[Entry]:
    """Entries of a PETSc options file, nested -options_file expanded in place (paths relative to the
    including file's directory). Raises ArgumentError (exit 1) for what PETSc would reject."""
    if os.path.realpath(path) in {os.path.realpath(p) for p in included_by}:
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
    entries: list[Entry] = []
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
    path = included_path(value, source if line else None)
    problem = file_problem(path)
    if problem == "no such file":
        raise ArgumentError(f"{where}: -options_file {value}: no such file{_where_looked(value, source, line)}",
                            EXIT_INPUT)
    if problem:
        raise ArgumentError(f"{where}: -options_file {value}: {problem}; give a PETSc options file", EXIT_INPUT)
    return read_options_file(path, included_by + ((source,) if line else ()))


def included_path(value: str, including: str | None) -> str:
    """Where ``-options_file value`` is: relative to the directory of the file ``including`` it, or to the
    working directory on the command line (``including`` None); an absolute path as it is."""
    if including is None or os.path.isabs(value):
        return value
    return os.path.normpath(os.path.join(os.path.dirname(including), value))


def _where_looked(value, source, line):
    if not line:
        return f" (paths on the command line are relative to the directory pfault runs in, {os.getcwd()})"
    base = os.path.dirname(source) or "."
    hint = ""
    if not os.path.isabs(value) and os.path.isfile(value):
        hint = f"; {value} of the working directory is {os.path.relpath(os.path.abspath(value), base)} from there"
    return f" (an included file is found relative to the file that includes it, in {base}{hint})"


def petsc_arguments(scene: str, rest: list[str]) -> list[str]:
    """The options of the scene file and then the command line ``rest``, as arguments for petsc4py.init, the
    options files (the scene, those it includes, ``-options_file`` on the command line) expanded in place: the
    later of two values wins, as when PETSc reads the files. Raises ArgumentError as read_options_file does."""
    args = _flatten(read_options_file(scene))
    i = 0
    while i < len(rest):
        token = rest[i]
        value = rest[i + 1] if i + 1 < len(rest) and not is_option_name(rest[i + 1]) else None
        if is_option_name(token) and _name(token) == "options_file":
            args += _flatten(_entry_or_include(token, value, COMMAND_LINE, 0, ()))
        else:
            args += [token] + ([] if value is None else [value])
        i += 1 if value is None else 2
    return args


def _flatten(entries):
    return [a for e in entries for a in ([f"-{e.name}"] if e.value is None else [f"-{e.name}", e.value])]


def replace_database(options: Any, args: list[str]) -> None:
    """Replaces every option of a running PETSc's database (``PETSc.Options()``) by those of ``args`` (as
    petsc_arguments gives them), as PETSc's start reads them from the command line: for a process that runs
    one scene after another, where no option of an earlier run may carry over."""
    for name in options.getAll():
        options.delValue("-" + name)
    i = 0
    while i < len(args):
        value = args[i + 1] if i + 1 < len(args) and not is_option_name(args[i + 1]) else None
        options.setValue(args[i], value)
        i += 1 if value is None else 2
