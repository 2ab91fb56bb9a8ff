"""The data files a run reads, recorded by size and SHA-256, and checked again when a run is continued.

Besides its options (options.txt), a run reads data files: the mesh (``-pfault_mesh_file``), a groundwater model's
heads and grid (``-pfault_heads_file``, ``-pfault_heads_grid``), every material property given as a field
(``-pfault_material_<material>_<property> field:FILE``) and the stations (``-pfault_stations``). ``scene_files``
lists them as their readers found them (pfault.paths.beside_scene); ``record`` hashes them on rank 0. The record,
a list of {option, path, size_bytes, sha256}, is written to ``input_files.json`` beside options.txt and
versions.json, and into every ``checkpoint.h5`` (JSON dataset ``input_files``).

A continued run (``-pfault_restart DIR``) compares its files with the record of DIR's checkpoint
(``check_restart``): the checkpoint is the answer to those files up to its time, so a file whose content differs
(changed in place, or another file under the option), one that run read and this one does not, or one this run
reads and that run did not, ends the run in one line before anything is written, unless the option that names it
is listed in ``-pfault_restart_changed_inputs`` (the user's statement that the continued steps are to read the file
as it is now; summary.json's ``restart.changed_inputs`` then lists each such file, then and now). A file moved
or copied elsewhere with the same content is the same file. A checkpoint without a record (written by an earlier
pfault) is continued with a warning that the files could not be checked.

Hashing reads each file once on rank 0 at start-up (hashlib, ~1 GB/s; the example site's files take well under
a millisecond, docs/outputs.md).
"""

from __future__ import annotations

import hashlib
import json
import os
from typing import Any

from .errors import InputError, run_on_root, warn
from .io.output import open_h5
from .materials.properties import field_refs
from .paths import beside_scene

JSON_NAME = "input_files.json"      # in the run directory, beside options.txt and versions.json
DATASET = "input_files"             # JSON dataset of checkpoint.h5
CHANGED_OPTION = "pfault_restart_changed_inputs"
# observations a continued run may leave out (they are output: pfault.io.run_options.RESTART_MAY_CHANGE)
MAY_DROP = ("pfault_stations",)
# the options that name a data file (besides the material properties given as field:FILE); the other options that
# name a path name no data (tests/unit/test_data_files.py keeps the two lists complete)
FILE_OPTIONS = ("pfault_mesh_file", "pfault_heads_file", "pfault_heads_grid", "pfault_stations", "pfault_crs",
                "pfault_insar_grid")


def scene_files(scene: Any, stations_file: str, scene_file: str) -> list[tuple[str, str]]:
    """(option, path) of every data file the run of ``scene`` (pfault.model.Scene) reads, each path as its reader
    found it: the mesh, the heads and their grid, the material properties' fields (found beside the scene file
    ``scene_file`` as pfault.materials.properties.read_fields finds them), the stations (``stations_file``, '' for
    none) and the CRS's .prj/.wkt file."""
    files = []
    if scene.settings.mesh_file:
        files.append(("pfault_mesh_file", scene.settings.mesh_file))
    heads = scene.heads_settings
    if heads is not None:
        files.append(("pfault_heads_file", heads.file))
        if heads.grid:
            files.append(("pfault_heads_grid", heads.grid))
    files += [(ref.option, beside_scene(ref.path, scene_file))
              for ref in field_refs(scene.materials, scene.flow_settings, scene.soils)]
    if stations_file:
        files.append(("pfault_stations", stations_file))
    if scene.georef is not None and scene.georef.crs_file:      # a .prj/.wkt file (heads in another CRS are reprojected by it)
        files.append(("pfault_crs", scene.georef.crs_file))
    return files


def describe(option: str, path: str) -> dict[str, Any]:
    """{option, path (absolute), size_bytes, sha256} of one data file."""
    try:
        with open(path, "rb") as fh:
            digest = hashlib.file_digest(fh, "sha256").hexdigest()
        size = os.path.getsize(path)
    except OSError as exc:
        raise InputError(f"-{option} {path}: cannot be read again to record it ({exc.strerror}); keep the data "
                         "files of a run in place while it runs") from None
    return {"option": option, "path": os.path.abspath(path), "size_bytes": int(size), "sha256": digest}


def record(comm: Any, files: list[tuple[str, str]]) -> list[dict[str, Any]]:
    """The record of ``files`` [(option, path)], hashed on rank 0 and known to every rank. Collective."""
    entries = run_on_root(comm, lambda: [describe(option, path) for option, path in files])
    return comm.tompi4py().bcast(entries, root=0)


def recorded(run_dir: str, checkpoint_name: str) -> list[dict[str, Any]] | None:
    """The record in the checkpoint ``checkpoint_name`` of ``run_dir``, None when it has none (rank 0)."""
    with open_h5(os.path.join(run_dir, checkpoint_name), "r") as h5:
        if DATASET not in h5:
            return None
        return json.loads(bytes(h5[DATASET][()]).decode())


def differences(then: list[dict[str, Any]], now: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The options whose files differ between the record ``then`` (of the run continued) and ``now``, in the order
    of the records: {option, then, now}, each side an entry of its record or None (no file for that option). A file
    is the same when its size and hash are; an observation file that this run leaves out (MAY_DROP) is no
    difference."""
    old = {e["option"]: e for e in then}
    new = {e["option"]: e for e in now}
    out = []
    for option in list(new) + [o for o in old if o not in new]:
        a, b = old.get(option), new.get(option)
        if b is None and option in MAY_DROP:
            continue
        if a is None or b is None or (a["size_bytes"], a["sha256"]) != (b["size_bytes"], b["sha256"]):
            out.append({"option": option, "then": _file(a), "now": _file(b)})
    return out


def _file(entry: dict[str, Any] | None) -> dict[str, Any] | None:
    """An entry without its option: {path, size_bytes, sha256}."""
    return None if entry is None else {k: v for k, v in entry.items() if k != "option"}


def _what(diff: dict[str, Any]) -> str:
    """How one file differs, for the message."""
    a, b, option = diff["then"], diff["now"], diff["option"]
    if a is None:
        return f"-{option} {b['path']} is a file that run did not read"
    if b is None:
        return f"that run read -{option} {a['path']}, this one reads no file for it"
    sizes = f"now {b['size_bytes']:,} bytes, SHA-256 {b['sha256'][:12]}...; then {a['size_bytes']:,} bytes, " \
            f"{a['sha256'][:12]}..."
    if a["path"] == b["path"]:
        return f"-{option} {b['path']} has changed since that run read it ({sizes})"
    return f"-{option} now reads {b['path']}, which differs from the file that run read, {a['path']} ({sizes})"


def changed_message(run_dir: str, diffs: list[dict[str, Any]]) -> str:
    """The one line that ends a continued run whose data files differ from the checkpoint's record."""
    first = diffs[0]
    more = f" (and {', '.join('-' + d['option'] for d in diffs[1:])})" if len(diffs) > 1 else ""
    names = ",".join(d["option"] for d in diffs)
    return (f"-pfault_restart {run_dir}: {_what(first)}{more}; the checkpoint is the answer to the files that run "
            f"read: give those files to continue it as it was, or -{CHANGED_OPTION} {names} to continue with the "
            "files as they are now (the steps up to the checkpoint stay those of the old files)")


def read_changed_inputs(reader: Any) -> tuple[str, ...]:
    """-pfault_restart_changed_inputs: the options (with or without the leading '-') whose data files may differ
    from those of the run -pfault_restart continues. Every rank, before the scene's options are checked."""
    names = tuple(n.lstrip("-").lower() for n in reader.get(CHANGED_OPTION))
    if names and not reader.get("pfault_restart"):
        raise InputError(f"-{CHANGED_OPTION}: only with -pfault_restart DIR (it names the data files that may "
                         "differ from those of the run DIR continues); remove it")
    return names


def check_restart(comm: Any, run_dir: str, checkpoint_name: str, now: list[dict[str, Any]],
                  accepted: tuple[str, ...]) -> dict[str, Any]:
    """Compare this run's record ``now`` with that of the checkpoint it continues; InputError on every rank where
    files differ that ``accepted`` (-pfault_restart_changed_inputs) does not name, or where it names an option
    that names no data file of either run. Returns what summary.json's ``restart`` adds: ``inputs_checked`` and
    ``changed_inputs``. Collective."""
    def compare():
        then = recorded(run_dir, checkpoint_name)
        options = [e["option"] for e in now]
        unknown = [n for n in accepted if n not in options + [e["option"] for e in then or ()]]
        if unknown:
            have = ", ".join(options) or "none"
            raise InputError(f"-{CHANGED_OPTION} {unknown[0]}: -{unknown[0]} names no data file of this run or of "
                             f"the run in -pfault_restart {run_dir}; the options that name this run's data files: "
                             f"{have}")
        if then is None:
            return None
        diffs = differences(then, now)
        refused = [d for d in diffs if d["option"] not in accepted]
        if refused:
            raise InputError(changed_message(run_dir, refused))
        return diffs
    diffs = comm.tompi4py().bcast(run_on_root(comm, compare), root=0)
    if diffs is None:
        warn(comm, f"-pfault_restart {run_dir}: its checkpoint.h5 holds no record of the data files that run read "
                   "(written by an earlier pfault), so they could not be checked: the continued steps read the "
                   "files as they are now, which must be those of that run for it to continue as it was")
        return {"inputs_checked": False, "changed_inputs": []}
    if diffs:
        warn(comm, f"-pfault_restart {run_dir}: continuing with changed data files, as -{CHANGED_OPTION} says: "
                   + "; ".join(_what(d) for d in diffs))
    return {"inputs_checked": True, "changed_inputs": diffs}
