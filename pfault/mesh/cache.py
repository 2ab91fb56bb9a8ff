"""Meshes of the built-in gmsh generators kept between runs, so that a geometry is meshed once.

gmsh meshes Wuxi at the paper's size in 4-6 s and Queretaro in 4-5 s, every run the same mesh (one thread, a
fixed seed: pfault.mesh.geometry). The mesh is stored on rank 0 as an uncompressed ``.npz`` of the SerialMesh's
arrays (20-50 ms to read back), in ``-pfault_mesh_cache`` (default: the user's cache directory,
``$XDG_CACHE_HOME/pfault/meshes``, else ``~/.cache/pfault/meshes``), under a name that is the SHA-256 of its key:
the generator, its options (size factor and geometry parameters, as the run read them) and the generator's code
version (the SHA-256 of the modules that build the mesh, and gmsh's version). A change of any of them is another
file; the key is stored in the file too and compared on reading.

Safe under concurrent runs: a file is written under a temporary name in the same directory and renamed into place
(atomic on POSIX), so a reader sees a whole file or none; two runs writing the same mesh write the same bytes. A
file that cannot be read (cut short by a full disk, another format) is meshed again and replaced. A directory that
cannot be written is a warning, and the run goes on with the mesh it built. The directory is kept under
``LIMIT_BYTES``: the least recently used files go first.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
import zipfile
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from .serial import SerialMesh

NONE = "none"               # -pfault_mesh_cache none: mesh every run
LIMIT_BYTES = 1 << 30       # the cache directory's size, beyond which the least recently used files are removed
FORMAT = 1                  # of the stored arrays; part of the key
# the modules whose code makes the mesh of a built-in generator
_CODE = ("geometry.py", "gmsh_io.py", "serial.py", "cache.py")


def default_dir() -> str:
    """The user's cache directory for meshes: $XDG_CACHE_HOME/pfault/meshes, else ~/.cache/pfault/meshes."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "pfault", "meshes")


def code_version() -> str:
    """SHA-256 of the generator's modules and gmsh's version: a mesh cached by other code is not reused."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in _CODE:
        h.update((here / name).read_bytes())
    try:
        h.update(metadata.version("gmsh").encode())
    except metadata.PackageNotFoundError:
        h.update(b"gmsh ?")
    return h.hexdigest()


def mesh_key(generator: str, options: dict[str, Any], version: str | None = None) -> str:
    """The key of a generator's mesh: its name, its options (JSON, sorted) and the code version."""
    return json.dumps({"generator": generator, "options": options, "code": version or code_version(),
                       "format": FORMAT}, sort_keys=True, default=list)


def _path(directory: str, key: str) -> str:
    return os.path.join(directory, hashlib.sha256(key.encode()).hexdigest()[:32] + ".npz")


def _load(path: str, key: str) -> SerialMesh | None:
    """The mesh stored at ``path`` under ``key``; None when there is none or it cannot be read."""
    try:
        with np.load(path, allow_pickle=False) as f:
            if str(f["key"]) != key:
                return None
            names = json.loads(str(f["names"]))
            surfaces = {name: f[f"surface_{i}"] for i, name in enumerate(names["surfaces"])}
            mesh = SerialMesh(points=f["points"], tets=f["tets"], cell_material=f["cell_material"],
                              material_names=names["materials"], surfaces=surfaces, source=names["source"])
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    os.utime(path)          # recently used
    return mesh


def _store(path: str, key: str, mesh: SerialMesh) -> None:
    """Write ``mesh`` under a temporary name beside ``path``, then rename it into place."""
    directory = os.path.dirname(path)
    os.makedirs(directory, exist_ok=True)
    names = {"materials": list(mesh.material_names), "surfaces": list(mesh.surfaces), "source": mesh.source}
    arrays = {f"surface_{i}": tri for i, tri in enumerate(mesh.surfaces.values())}
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".", suffix=".npz.tmp")
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)          # as an ordinary file of the user's (mkstemp makes it 0600)
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, key=np.array(key), names=np.array(json.dumps(names)), points=mesh.points, tets=mesh.tets,
                     cell_material=mesh.cell_material, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _prune(directory: str, limit: int) -> None:
    """Remove the least recently used meshes until the directory holds at most ``limit`` bytes."""
    files = []
    for p in Path(directory).glob("*.npz"):
        try:
            st = p.stat()
        except OSError:
            continue
        files.append((st.st_mtime, st.st_size, p))
    total = sum(size for _, size, _ in files)
    for _, size, p in sorted(files, key=lambda f: f[0]):
        if total <= limit:
            break
        p.unlink(missing_ok=True)
        total -= size


def cached_mesh(directory: str, key: str, build: Callable[[], SerialMesh], limit: int = LIMIT_BYTES) -> SerialMesh:
    """The mesh of ``key`` from the cache ``directory``, or ``build()``'s, stored there for the next run (rank 0).
    ``directory`` NONE: ``build()`` every time."""
    if directory == NONE:
        return build()
    path = _path(directory, key)
    mesh = _load(path, key) if os.path.exists(path) else None
    if mesh is not None:
        return mesh.check()
    mesh = build()
    try:
        _store(path, key, mesh)
        _prune(directory, limit)
    except OSError as exc:
        sys.stderr.write(f"pfault: warning: -pfault_mesh_cache {directory}: the mesh is not kept for the next run "
                         f"({exc.strerror or exc}); give a directory that can be written, or none\n")
        sys.stderr.flush()
    return mesh
