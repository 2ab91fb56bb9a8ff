"""Run output in the serial (partition-independent) numbering, written by rank 0 (on more than one rank the
per-step datasets of the volume fields and the faults, and the checkpoint, are written by every rank,
pfault.io.parallel).

- ``fields.xdmf`` + ``fields.h5``: time series readable by ParaView and meshio.xdmf.TimeSeriesReader
- ``fault.xdmf`` + ``fault.h5`` (faults), ``surface.xdmf`` + ``surface.h5`` (land surface, hazard fields)
- ``options.txt``: the resolved options database; ``versions.json``: package versions and git hash;
  ``input_files.json``: the data files the run read, with their sizes and SHA-256 (pfault.provenance)
- ``summary.json``: scene, ranks, mesh sizes, per-step solver figures, maxima, wall times and each rank's
  peak memory
- ``checkpoint.h5``: the state after the last completed step (pfault.io.checkpoint)

Every completed step is durable: its HDF5 datasets are flushed, then the XDMF files and summary.json are
rewritten whole into a temporary file that replaces the old one (os.replace), so a reader never sees a
half-written file, whenever the run stops. A new run writes into a hidden sibling directory and takes the
place of the output directory after its first completed step (``commit``): until then a previous result
there stays intact; after it the directory holds only the new run's files (plus files pfault does not
write, which are carried over).
"""

from __future__ import annotations

import ctypes
import importlib
import importlib.metadata
import json
import os
import platform
import shutil
import subprocess
import sys
from collections.abc import Iterable, Sequence
from typing import Any

import h5py
import numpy as np

from .. import __version__

# names pfault writes into a run directory: replaced by a new run; anything else there is carried over
SERIES = ("fields", "fault", "surface")
RUN_FILES = frozenset([f"{s}.{e}" for s in SERIES for e in ("xdmf", "h5")]
                      + ["summary.json", "options.txt", "versions.json", "materials.json", "input_files.json",
                         "checkpoint.h5",
                         "fault_opening_slip.png", "subsidence_map.png", "histories.png", "hazard_map.png",
                         "fissure_break.png",
                         # observations (pfault.io.stations, pfault.io.insar)
                         "station_displacement.csv", "station_displacement.h5", "insar_los.nc", "insar_los.png"])
TMP_SUFFIX = ".tmp"
OPTIONS = "options.txt"         # the resolved options: one "-name value" (or "-name") per line

# what an XDMF file says of a dataset, (shape, dtype), and of a written step, (group path, time, its datasets)
Description = tuple[tuple[int, ...], np.dtype]
XdmfEntry = tuple[str, float, list[tuple[str, str, Description]]]


def package_versions() -> dict[str, str | None]:
    # here, not at the top: the post-processing that reads run directories (pfault.post) starts no MPI nor PETSc
    import mpi4py
    import petsc4py
    from petsc4py import PETSc
    versions: dict[str, str | None] = {
        "pfault": __version__, "python": platform.python_version(), "numpy": np.__version__,
        "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()), "petsc4py": petsc4py.__version__,
        "mpi4py": mpi4py.__version__}
    for name in ("meshio", "gmsh", "h5py"):
        versions[name] = _module_version(name)
    versions["git"] = git_hash()
    return versions


def _module_version(name: str) -> str | None:
    """A package's version: its module's own where it is imported, else its installed metadata (importing meshio
    and gmsh only to read theirs took 0.2 s of a run whose mesh came from the cache), else its module's; None where
    it is not installed."""
    mod = sys.modules.get(name)
    if mod is None:
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:     # (Debian's h5py has no metadata)
            try:
                mod = importlib.import_module(name)
            except ImportError:
                return None
    return getattr(mod, "__version__", "?")


def git_hash() -> str | None:
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        out = subprocess.run(["git", "-C", here, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", here, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    return out.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


def replace_text(path: str, text: str, tmp: str | None = None) -> None:
    """Write a text file whole: into a temporary sibling (``tmp``, default ``path`` + TMP_SUFFIX), then
    os.replace (atomic on POSIX)."""
    tmp = path + TMP_SUFFIX if tmp is None else tmp
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)


def replace_json(path: str, data: Any, tmp: str | None = None) -> None:
    replace_text(path, json.dumps(data, indent=2) + "\n", tmp)


def record_failure(directory: str, line: str, code: int, not_converged: bool = False) -> None:
    """The summary.json in ``directory`` (that of the run's last completed step) says how the run ended:
    ``running`` false, the ``error`` line and the ``exit_code`` (``converged`` false when a solve failed).

    Any rank may call it, the one that failed alone before it aborts the job included (the others then wait
    in a collective call and write nothing); the temporary file is named after the writing process, so that
    two writers never share one."""
    path = os.path.join(directory, "summary.json")
    with open(path) as fh:
        summary = json.load(fh)
    summary.update(running=False, error=line, exit_code=int(code))
    if not_converged:
        summary["converged"] = False
    replace_json(path, summary, tmp=f"{path}.{os.getpid()}{TMP_SUFFIX}")


def read_options(run_dir: str) -> dict[str, str]:
    """The options of the run in ``run_dir`` as its options.txt holds them (RunWriter.write_metadata): {name without
    '-': value string ('' for a flag)}."""
    out = {}
    with open(os.path.join(run_dir, OPTIONS)) as fh:
        for line in fh:
            if line.startswith("-"):
                name, _, value = line[1:].rstrip("\n").partition(" ")
                out[name] = value
    return out


def open_h5(path: str, mode: str) -> h5py.File:
    """h5py File without HDF5's file lock, so that a viewer may read what has been flushed while a run
    writes (HDF5 >= 1.10.7; older versions lock)."""
    try:
        return h5py.File(path, mode, locking=False)
    except (TypeError, ValueError):
        return h5py.File(path, mode)


# ------------------------------------------------------------------------------------------------------
# XDMF time series
# ------------------------------------------------------------------------------------------------------
_TOPOLOGY = {4: "Tetrahedron", 3: "Triangle"}


def describe(arr: np.ndarray | h5py.Dataset) -> Description:
    """(shape, dtype) of an array or dataset: what the XDMF file says about it (nothing is read)."""
    return tuple(arr.shape), np.dtype(arr.dtype)


def _data_item(h5name, path, desc):
    shape, dtype = desc
    kind = "Int" if np.issubdtype(dtype, np.integer) else "Float"
    dims = " ".join(str(d) for d in shape)
    return (f'<DataItem DataType="{kind}" Dimensions="{dims}" Format="HDF" Precision="{dtype.itemsize}">'
            f"{h5name}:{path}</DataItem>")


def _attribute_type(shape):
    if len(shape) == 1:
        return "Scalar"
    return {3: "Vector", 9: "Tensor"}.get(shape[1], "Matrix")


def write_xdmf(directory: str, name: str, mesh: tuple[Description, Description],
               entries: Iterable[XdmfEntry]) -> None:
    """``NAME.xdmf``: the mesh (``mesh``: descriptions of /mesh/points and /mesh/cells) and the steps in
    ``entries`` [(group path, time, [(dataset name, center, description)])], from what was written, without
    reading the HDF5 file back."""
    h5 = name + ".h5"
    points, cells = mesh
    lines = ['<?xml version="1.0"?>',
             '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">', "  <Domain>",
             '    <Grid Name="mesh" GridType="Uniform">',
             f'      <Geometry GeometryType="XYZ">{_data_item(h5, "/mesh/points", points)}</Geometry>',
             f'      <Topology TopologyType="{_TOPOLOGY[cells[0][1]]}" NumberOfElements="{cells[0][0]}">'
             f'{_data_item(h5, "/mesh/cells", cells)}</Topology>',
             "    </Grid>",
             '    <Grid Name="TimeSeries" GridType="Collection" CollectionType="Temporal">']
    ptr = 'xpointer(//Grid[@Name=&quot;mesh&quot;]/*[self::Topology or self::Geometry])'
    for path, t, fields in entries:
        lines.append(f'      <Grid Name="step {int(path.rsplit("/", 1)[-1])}" GridType="Uniform">')
        lines.append(f'        <xi:include xpointer="{ptr}"/>')
        lines.append(f'        <Time Value="{t!r}"/>')
        for key, center, desc in fields:
            lines.append(f'        <Attribute Name="{key}" AttributeType="{_attribute_type(desc[0])}" '
                         f'Center="{center}">{_data_item(h5, f"{path}/{key}", desc)}</Attribute>')
        lines.append("      </Grid>")
    lines += ["    </Grid>", "  </Domain>", "</Xdmf>", ""]
    replace_text(os.path.join(directory, name + ".xdmf"), "\n".join(lines))


def step_entry(grp: h5py.Group) -> XdmfEntry:
    """The XDMF entry of a written step group."""
    return grp.name, float(grp.attrs["time"]), [(k, ds.attrs["center"], describe(ds)) for k, ds in grp.items()]


class XdmfSeries:
    """One time series: ``NAME.h5`` holds the mesh (``/mesh``) and one group per written step
    (``/steps/NNNNNN``, attributes ``step`` and ``time``; datasets with attribute ``center`` Node or Cell);
    ``NAME.xdmf`` lists the steps written so far in the layout of meshio's TimeSeriesWriter (readable by
    meshio.xdmf.TimeSeriesReader and ParaView). Rank 0 only (pfault.io.parallel.ParallelSeries continues one
    on every rank)."""

    def __init__(self, directory: str, name: str, points: np.ndarray, cells: np.ndarray) -> None:
        self.directory, self.name = directory, name
        self.h5name = name + ".h5"
        self.h5 = open_h5(os.path.join(directory, self.h5name), "w")
        mesh = self.h5.create_group("mesh")
        points = mesh.create_dataset("points", data=np.asarray(points, dtype=np.float64))
        cells = mesh.create_dataset("cells", data=np.asarray(cells, dtype=np.int64))
        self.mesh = describe(points), describe(cells)
        self.n_points, self.n_cells = len(points), len(cells)
        self.entries: list[XdmfEntry] = []      # (group path, time, [(name, center, (shape, dtype))])
        self.h5.flush()
        self._write_xdmf()

    def write_step(self, step: int, t: float, point_data: dict[str, np.ndarray] | None = None,
                   cell_data: dict[str, np.ndarray] | None = None) -> None:
        grp = self.h5.create_group(f"steps/{int(step):06d}")
        grp.attrs["step"], grp.attrs["time"] = int(step), float(t)
        for center, data in (("Node", point_data or {}), ("Cell", cell_data or {})):
            for key, value in data.items():
                ds = grp.create_dataset(key, data=np.asarray(value))
                ds.attrs["center"] = center
        self.h5.flush()
        self.append(step_entry(grp))

    def append(self, entry: XdmfEntry) -> None:
        """A step was written into ``NAME.h5`` (here or by pfault.io.parallel.ParallelSeries): list it."""
        self.entries.append(entry)
        self._write_xdmf()

    def release(self) -> None:
        """Close ``NAME.h5`` so that every rank may open it to write the following steps (ParallelSeries);
        this object goes on listing them (``append``)."""
        self.close()

    def copy_steps(self, h5_path: str, last_step: int) -> None:
        """Copy the steps up to ``last_step`` of another run's series (same mesh) into this one (restart). A step
        is chosen by its group's name (the step number, six digits), without opening the group: a run killed
        outright while it wrote a later step may have left that group unreadable."""
        with open_h5(h5_path, "r") as old:
            if old["mesh/points"].shape != (self.n_points, 3) or len(old["mesh/cells"]) != self.n_cells:
                raise ValueError(f"{h5_path}: the mesh differs from this run's")
            for key in sorted(old.get("steps", {})):
                if int(key) <= last_step:
                    old.copy(old["steps"][key], self.h5.require_group("steps"), name=key)
                    self.entries.append(step_entry(self.h5["steps"][key]))
        self.h5.flush()
        self._write_xdmf()

    def _write_xdmf(self):
        write_xdmf(self.directory, self.name, self.mesh, self.entries)

    def moved(self, directory: str) -> None:
        """The run directory was renamed (the open HDF5 file moves with it)."""
        self.directory = directory

    def close(self) -> None:
        if self.h5 is not None:
            self.h5.close()
            self.h5 = None


# ------------------------------------------------------------------------------------------------------
# the run directory
# ------------------------------------------------------------------------------------------------------
def _exchange(a, b):
    """Swap two directories atomically (Linux renameat2 RENAME_EXCHANGE); False where not supported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def staging_dir(path: str) -> str:
    """The hidden sibling ``.<name>.pfault-<host>-<pid>`` a run writes into before its first completed step;
    stale ones left by killed runs on this host (their process is gone) are removed."""
    parent, base = os.path.split(os.path.abspath(path))
    os.makedirs(parent, exist_ok=True)
    prefix = f".{base}.pfault-{platform.node()}-"
    for entry in os.listdir(parent):
        pid = entry[len(prefix):]
        if entry.startswith(prefix) and pid.isdigit() and not _pid_alive(int(pid)):
            shutil.rmtree(os.path.join(parent, entry), ignore_errors=True)
    stage = os.path.join(parent, f"{prefix}{os.getpid()}")
    shutil.rmtree(stage, ignore_errors=True)
    os.makedirs(stage)
    return stage


class RunWriter:
    """Writes a run's directory; every method is called on rank 0 only (the series it releases are written
    by every rank, pfault.io.parallel).

    ``path`` is the output directory; the files go to a staging sibling until ``commit`` puts them in place
    (``self.dir`` is where they are now)."""

    def __init__(self, path: str, points: np.ndarray, cells: np.ndarray, cell_material: np.ndarray,
                 material_names: Sequence[str], fault_mesh: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 surface_mesh: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        self.path = os.path.realpath(path)     # a symbolic link to a directory: the run goes where it points
        if os.path.exists(self.path) and not os.path.isdir(self.path):
            raise FileExistsError(f"{path} exists and is not a directory")
        self.dir = staging_dir(self.path)
        self.committed = False
        self.cell_material = np.asarray(cell_material, dtype=np.int64)
        self.material_names = material_names
        self.series = {"fields": XdmfSeries(self.dir, "fields", points, cells)}
        if fault_mesh is not None:
            fpoints, ffaces, fid = fault_mesh
            self.series["fault"] = XdmfSeries(self.dir, "fault", fpoints, ffaces)
            self.fault_id = np.asarray(fid, dtype=np.int64)
        if surface_mesh is not None:
            self.series["surface"] = XdmfSeries(self.dir, "surface", *surface_mesh)

    def file(self, name: str) -> str:
        return os.path.join(self.dir, name)

    def write_step(self, step: int, t: float, point_data: dict[str, np.ndarray],
                   cell_data: dict[str, np.ndarray]) -> None:
        cd = {"material": self.cell_material}
        cd.update(cell_data)
        self.series["fields"].write_step(step, t, point_data, cd)

    def write_fault_step(self, step: int, t: float, data: dict[str, np.ndarray]) -> None:
        cd = {"fault": self.fault_id}
        cd.update(data)
        self.series["fault"].write_step(step, t, None, cd)

    def write_surface_step(self, step: int, t: float, point_data: dict[str, np.ndarray],
                           cell_data: dict[str, np.ndarray]) -> None:
        self.series["surface"].write_step(step, t, point_data, cell_data)

    def release(self, names: Iterable[str]) -> None:
        """The series ``names`` are written by every rank from now on (pfault.io.parallel): their HDF5 files
        are closed here and their steps come through ``add_steps``."""
        for name in names:
            self.series[name].release()

    def add_steps(self, entries: dict[str, XdmfEntry]) -> None:
        """Steps written by every rank into released series: {series name: XDMF entry}."""
        for name, entry in entries.items():
            self.series[name].append(entry)

    def continue_from(self, run_dir: str, last_step: int) -> None:
        """Restart: the output steps up to ``last_step`` of the run in ``run_dir`` start this run's series, and
        its checkpoint is this run's until this run writes one (a first step that fails leaves it)."""
        for name, series in self.series.items():
            old = os.path.join(run_dir, name + ".h5")
            if os.path.exists(old):
                series.copy_steps(old, last_step)
        shutil.copyfile(os.path.join(run_dir, "checkpoint.h5"), self.file("checkpoint.h5"))

    def write_metadata(self, options: dict[str, Any], argv: Sequence[str],
                       metadata: dict[str, Any] | None = None) -> None:
        """options.txt, versions.json, materials.json and one ``NAME.json`` per entry of ``metadata`` (the data
        files the run reads: input_files.json)."""
        for name, value in (metadata or {}).items():
            replace_json(self.file(name + ".json"), value)
        lines = ["# resolved options of this run (command: %s)" % " ".join(argv)]
        for k in sorted(options):
            v = options[k]
            lines.append(f"-{k} {v}" if v not in (None, "") else f"-{k}")
        replace_text(self.file(OPTIONS), "\n".join(lines) + "\n")
        replace_json(self.file("versions.json"), package_versions())
        replace_json(self.file("materials.json"), {i: n for i, n in enumerate(self.material_names)})

    def write_summary(self, summary: dict[str, Any]) -> None:
        replace_json(self.file("summary.json"), summary)

    def write_failure(self, line: str, code: int, not_converged: bool = False) -> None:
        """A run that ends with an error after its directory was put in place: its summary.json (that of
        the last completed step) says so, with ``running`` false, the ``error`` line and the ``exit_code``
        (``converged`` false when a solve failed). Nothing before the commit: a previous result stays."""
        if self.committed:
            record_failure(self.dir, line, code, not_converged)

    def commit(self) -> None:
        """Put the staged run in place of the output directory (once, after the first completed step).

        Files of the old directory that pfault does not write (logs of a driver, notes) are moved into the
        new one first (an open file keeps being written where it moved); then the two directories are swapped
        atomically where the kernel can (renameat2), else by two renames; the old run's files are deleted."""
        if self.committed:
            return
        path = self.path
        if os.path.isdir(path):
            for entry in os.listdir(path):
                if entry not in RUN_FILES and not entry.endswith(TMP_SUFFIX) and \
                        not os.path.exists(os.path.join(self.dir, entry)):
                    os.rename(os.path.join(path, entry), os.path.join(self.dir, entry))
            if _exchange(self.dir, path):
                old = self.dir
            else:
                old = self.dir + ".old"
                os.rename(path, old)
                os.rename(self.dir, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(self.dir, path)
        self.dir = path
        for series in self.series.values():
            series.moved(path)
        self.committed = True

    def close(self) -> None:
        for series in self.series.values():
            series.close()

    def abandon(self) -> None:
        """A run that ends before its first completed step: remove what it staged; the output directory
        (a previous result) is left as it was."""
        self.close()
        if not self.committed:
            shutil.rmtree(self.dir, ignore_errors=True)
