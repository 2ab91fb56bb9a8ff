"""Files named in a scene: a relative path is taken from the working directory, or else from the directory of the
scene file that names it (so a scene and its data files travel together)."""

from __future__ import annotations

import os


def beside_scene(path: str, scene_file: str) -> str:
    """``path`` as given if it is absolute or exists from the working directory, else the path beside
    ``scene_file`` if that exists, else ``path`` unchanged (the caller's error then names it as given)."""
    if not path or os.path.isabs(path) or os.path.exists(path) or not scene_file:
        return path
    other = os.path.normpath(os.path.join(os.path.dirname(scene_file), path))
    return other if os.path.exists(other) else path
