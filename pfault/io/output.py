"""Run output written by rank 0 in the serial (partition-independent) numbering.

- ``fields.xdmf`` + ``fields.h5``: time series readable by ParaView and meshio.xdmf.TimeSeriesReader
- ``options.txt``: the resolved options database; ``versions.json``: package versions and git hash
- ``summary.json``: scene, ranks, mesh sizes, per-step solver figures, maxima and wall times
"""

from __future__ import annotations

import json
import os
import pathlib
import platform
import subprocess
import sys

import numpy as np


def package_versions():
    from petsc4py import PETSc
    import mpi4py
    import petsc4py
    import pfault
    versions = {"pfault": pfault.__version__, "python": platform.python_version(), "numpy": np.__version__,
                "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()), "petsc4py": petsc4py.__version__,
                "mpi4py": mpi4py.__version__}
    for name in ("meshio", "gmsh", "h5py"):
        try:
            mod = __import__(name)
            versions[name] = getattr(mod, "__version__", "?")
        except ImportError:
            versions[name] = None
    versions["git"] = git_hash()
    return versions


def git_hash():
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


class RunWriter:
    """Writes a run's directory; every method is called on rank 0 only."""

    def __init__(self, path, points, cells, cell_material, material_names, fault_mesh=None):
        os.makedirs(path, exist_ok=True)
        self.path = path
        import meshio
        self._meshio = meshio
        for name in ("fields.xdmf", "fields.h5", "fault.xdmf", "fault.h5"):
            if os.path.exists(os.path.join(path, name)):
                os.remove(os.path.join(path, name))
        # meshio opens the .h5 beside the current directory, not beside the .xdmf: open it from there
        self._writer = meshio.xdmf.TimeSeriesWriter("fields.xdmf")
        cwd = os.getcwd()
        os.chdir(path)
        try:
            self._writer.__enter__()
        finally:
            os.chdir(cwd)
        self._writer.filename = pathlib.Path(os.path.abspath(os.path.join(path, "fields.xdmf")))
        self._writer.write_points_cells(points, [("tetra", np.asarray(cells, dtype=np.int64))])
        self.cell_material = np.asarray(cell_material, dtype=np.int64)
        self.material_names = material_names
        self._fault = None
        if fault_mesh is not None:
            self._fault = self._open("fault.xdmf")
            fpoints, ffaces, fid = fault_mesh
            self._fault.write_points_cells(fpoints, [("triangle", np.asarray(ffaces, dtype=np.int64))])
            self.fault_id = np.asarray(fid, dtype=np.int64)

    def _open(self, name):
        import meshio
        w = meshio.xdmf.TimeSeriesWriter(name)
        cwd = os.getcwd()
        os.chdir(self.path)
        try:
            w.__enter__()
        finally:
            os.chdir(cwd)
        w.filename = pathlib.Path(os.path.abspath(os.path.join(self.path, name)))
        return w

    def write_fault_step(self, t, data):
        cd = {"fault": [self.fault_id]}
        cd.update({k: [np.asarray(v)] for k, v in data.items()})
        self._fault.write_data(t, cell_data=cd)

    def write_step(self, t, point_data, cell_data):
        cd = {"material": [self.cell_material]}
        cd.update({k: [np.asarray(v)] for k, v in cell_data.items()})
        self._writer.write_data(t, point_data=point_data, cell_data=cd)

    def close(self):
        if self._writer is not None:
            self._writer.__exit__(None, None, None)
            self._writer = None
        if self._fault is not None:
            self._fault.__exit__(None, None, None)
            self._fault = None

    def write_metadata(self, options, argv):
        with open(os.path.join(self.path, "options.txt"), "w") as fh:
            fh.write("# resolved options of this run (command: %s)\n" % " ".join(argv))
            for k in sorted(options):
                v = options[k]
                fh.write(f"-{k} {v}\n" if v not in (None, "") else f"-{k}\n")
        with open(os.path.join(self.path, "versions.json"), "w") as fh:
            json.dump(package_versions(), fh, indent=2)
        with open(os.path.join(self.path, "materials.json"), "w") as fh:
            json.dump({i: n for i, n in enumerate(self.material_names)}, fh, indent=2)

    def write_summary(self, summary):
        tmp = os.path.join(self.path, "summary.json.tmp")
        with open(tmp, "w") as fh:
            json.dump(summary, fh, indent=2)
        os.replace(tmp, os.path.join(self.path, "summary.json"))
