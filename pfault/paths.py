"""Files named in a scene: a relative path is taken from the working directory, or else from the directory of the
scene file that names it (so a scene and its data files travel together); ``file_problem`` says why a path named
as a data file cannot be read, in the words every reader's message uses."""

from __future__ import annotations

import os


def beside_scene(path: str, scene_file: str) -> str:
    """``path`` as given if it is absolute or exists from the working directory, else the path beside
    ``scene_file`` if that exists, else ``path`` unchanged (the caller's error then names it as given)."""
    if not path or os.path.isabs(path) or os.path.exists(path) or not scene_file:
        return path
    other = os.path.normpath(os.path.join(os.path.dirname(scene_file), path))
    return other if os.path.exists(other) else path


def file_problem(path: str) -> str | None:
    """Why ``path`` cannot be read as a data file, or None when it can: ``no such file``, ``is a directory, not a
    file``, a broken symbolic link, not a regular file (a device or a pipe), or not readable. Each reader puts it
    after the option and the path and adds what the option wants."""
    if os.path.isdir(path):
        return "is a directory, not a file"
    if not os.path.exists(path):
        return "is a symbolic link to nothing (no such file)" if os.path.islink(path) else "no such file"
    if not os.path.isfile(path):
        return "is not a regular file (a device or a pipe)"
    if not os.access(path, os.R_OK):
        return "is not readable (permission denied)"
    return None
