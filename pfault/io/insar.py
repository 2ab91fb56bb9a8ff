"""The land surface's line-of-sight (LOS) displacement on a raster, as InSAR measures it: ``-pfault_insar_los
e,n,u`` (the unit vector from the ground to the satellite, east, north and up components) and
``-pfault_insar_spacing`` (pixel size, m).

At time 0 and at every output time, LOS = e ux + n uy + u uz of the displacement relative to the initial state,
positive towards the satellite (uplift seen from above is positive; subsidence negative), at the centre of every
pixel of a regular grid over the land surface (-pfault_ground_surface), and its rate between consecutive output
times. Pixels are squares aligned on multiples of the spacing in site coordinates (pfault.io.probes.mesh_to_site);
a pixel takes the value, in the P1 basis, of the surface triangle under its centre, on the side of a fault trace
its triangle lies; pixels whose centre is outside the land surface are no-data.

``insar_los.nc`` (CF-1.8 NetCDF-4, readable by GDAL/QGIS, xarray and the netCDF library): coordinates ``x``,
``y`` (m, site coordinates) and ``time`` (s from the start of the scene), variables ``los_displacement`` (m) and
``los_velocity`` (m s-1; no-data at the first time) on (time, y, x), with _FillValue at pixels outside the land
surface, and ``step`` (the step number of each time). The figure ``insar_los.png`` maps the last time's LOS
displacement and velocity. A restart keeps the times of the run it continues up to its checkpoint's step.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError, run_on_root
from .observers import Observer
from .probes import Located, PointProbe, Raster

NC_NAME = "insar_los.nc"
PNG_NAME = "insar_los.png"
FILL = -9999.0          # _FillValue of the pixels outside the land surface
# |los| within this of 1 is a unit vector (direction cosines rounded to two decimals are up to ~0.009 off); it is
# normalised
UNIT_TOL = 0.01


@dataclass(frozen=True)
class InsarSettings:
    los: np.ndarray             # (3,) unit vector east, north, up from the ground to the satellite
    spacing: float | None       # pixel size (m); None: the mean edge length of the land surface's triangles


def read_insar_settings(reader: Any) -> InsarSettings | None:
    """-pfault_insar_los and -pfault_insar_spacing (every rank); None without a LOS vector."""
    los = reader.get("pfault_insar_los")
    if not los:
        return None
    text = ",".join(f"{v:g}" for v in los)
    if len(los) != 3:
        raise InputError(f"-pfault_insar_los {text}: give three components e,n,u of the unit vector from the ground "
                         "to the satellite (e.g. -0.61,-0.11,0.785)")
    v = np.array(los, dtype=np.float64)
    norm = float(np.linalg.norm(v))
    if abs(norm - 1.0) > UNIT_TOL:
        raise InputError(f"-pfault_insar_los {text}: not a unit vector (length {norm:.4g}); give the east, north, "
                         "up components of the unit vector from the ground to the satellite (e.g. -0.61,-0.11,0.785)")
    spacing = reader.get("pfault_insar_spacing")
    if spacing is not None and not spacing > 0:
        raise InputError(f"-pfault_insar_spacing {spacing:g}: the pixel size must be positive (m), e.g. 50*m")
    return InsarSettings(v / norm, spacing)


def check_continuation(raster: Raster, los: np.ndarray, run_dir: str) -> dict[str, np.ndarray]:
    """A restart continues the LOS raster of the run in ``run_dir``: it has one, of the same pixels and LOS
    vector; returns its arrays (read_netcdf)."""
    path = os.path.join(run_dir, NC_NAME)
    if not os.path.exists(path):
        raise InputError(f"-pfault_insar_los: the run in -pfault_restart {run_dir} has no LOS raster ({NC_NAME}); "
                         "continue it without -pfault_insar_los, or run the scene from the start with it")
    old = read_netcdf(path)
    same = (np.array_equal(old["x"], raster.x) and np.array_equal(old["y"], raster.y)
            and np.allclose(old["los"], los, rtol=0, atol=1e-12))
    if not same:
        raise InputError(f"-pfault_insar_los: the LOS vector or the pixels differ from those of the run in "
                         f"-pfault_restart {run_dir}; give the -pfault_insar_los and -pfault_insar_spacing it had")
    return old


class InsarSeries:
    """The LOS raster of a run (rank 0): ``insar_los.nc`` made whole at the start (time 0, or the times of the run
    a restart continues), then one time appended in place per output time (the file is closed after each, so a
    reader sees every time written). The last map and its time are kept for the velocity."""

    def __init__(self, raster: Raster, los: np.ndarray) -> None:
        self.raster, self.los = raster, los
        self.last: tuple[float, np.ndarray] | None = None

    def start(self, directory: str, restart_dir: str | None, restart_step: int | None) -> None:
        if restart_dir:
            steps, times, maps = self._continue(restart_dir, int(restart_step or 0))
        else:
            steps, times, maps = [0], [0.0], np.where(self.raster.inside, 0.0, np.nan)[None]
        write_netcdf(os.path.join(directory, NC_NAME), self.raster, self.los, steps, times, maps)
        self.last = (float(times[-1]), maps[-1])

    def _continue(self, run_dir: str, last_step: int) -> tuple:
        old = check_continuation(self.raster, self.los, run_dir)
        keep = old["step"] <= last_step
        return old["step"][keep], old["time"][keep], old["los_displacement"][keep]

    def append(self, directory: str, step: int, t: float, u: np.ndarray) -> None:
        """``u`` (k, 3): the displacement at the pixels inside the land surface."""
        los = np.full(self.raster.inside.shape, np.nan)
        los[self.raster.inside] = u @ self.los
        t_prev, prev = self.last
        append_netcdf(os.path.join(directory, NC_NAME), step, t, los, (los - prev) / (t - t_prev))
        self.last = (float(t), los)


def velocities(times: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """LOS velocity at each time since the previous one (NaN at the first)."""
    rate = np.full_like(maps, np.nan)
    if len(times) > 1:
        rate[1:] = (maps[1:] - maps[:-1]) / (times[1:] - times[:-1])[:, None, None]
    return rate


def write_netcdf(path: str, raster: Raster, los: np.ndarray, steps: Sequence[int], times: Sequence[float], maps: np.ndarray) -> None:
    """``insar_los.nc`` (CF-1.8, NetCDF-4 through h5netcdf) with the given times, written into ``path``.tmp and
    renamed; its time dimension is unlimited (``append_netcdf``)."""
    import h5netcdf
    import pfault
    disp = np.asarray(maps, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    tmp = path + ".tmp"
    with h5netcdf.File(tmp, "w") as nc:
        nc.attrs.update({
            "Conventions": "CF-1.8", "title": "line-of-sight displacement of the land surface",
            "source": f"pfault {pfault.__version__}",
            "los_unit_vector_enu": los.astype(np.float64),
            "comment": "LOS = e ux + n uy + u uz of the displacement relative to the initial state, positive "
                       "towards the satellite (e, n, u: unit vector from the ground to the satellite); pixels "
                       "outside the land surface hold _FillValue; x, y in site coordinates (m)"})
        nc.dimensions = {"time": None, "y": len(raster.y), "x": len(raster.x)}
        nc.resize_dimension("time", len(t))
        for name, values, axis in (("x", raster.x, "X"), ("y", raster.y, "Y")):
            v = nc.create_variable(name, (name,), np.float64, data=values)
            v.attrs.update({"standard_name": f"projection_{name}_coordinate", "units": "m", "axis": axis,
                            "long_name": f"{name} of the pixel centre (site coordinates)"})
        v = nc.create_variable("time", ("time",), np.float64)
        v[:] = t
        # seconds, not "seconds since" a date: a scene has no calendar date, and CF's time axis needs one
        v.attrs.update({"units": "s", "long_name": "time from the start of the scene"})
        v = nc.create_variable("step", ("time",), np.int64)
        v[:] = np.asarray(steps, dtype=np.int64)
        v.attrs["long_name"] = "pfault step number of the output time"
        chunks = (1, len(raster.y), len(raster.x))              # one map per chunk: appended whole
        for name, values, units, long in (
                ("los_displacement", disp, "m", "line-of-sight displacement relative to the initial state, "
                                                "positive towards the satellite"),
                ("los_velocity", velocities(t, disp), "m s-1", "line-of-sight velocity between the previous output "
                                                               "time and this one, positive towards the satellite")):
            v = nc.create_variable(name, ("time", "y", "x"), np.float64, fillvalue=FILL, chunks=chunks)
            v[:] = np.where(np.isnan(values), FILL, values)
            v.attrs.update({"units": units, "long_name": long})
    os.replace(tmp, path)


def append_netcdf(path: str, step: int, t: float, los: np.ndarray, rate: np.ndarray) -> None:
    """One more time in ``insar_los.nc``: its step, time, LOS map and velocity (NaN: no-data)."""
    import h5netcdf
    with h5netcdf.File(path, "a") as nc:
        k = nc.dimensions["time"].size
        nc.resize_dimension("time", k + 1)
        nc.variables["time"][k] = float(t)
        nc.variables["step"][k] = int(step)
        nc.variables["los_displacement"][k] = np.where(np.isnan(los), FILL, los)
        nc.variables["los_velocity"][k] = np.where(np.isnan(rate), FILL, rate)


def read_netcdf(path: str) -> dict[str, np.ndarray]:
    """The arrays of an ``insar_los.nc`` (no-data as NaN)."""
    import h5netcdf
    with h5netcdf.File(path, "r") as nc:
        out = {k: nc.variables[k][()] for k in ("x", "y", "time", "step", "los_displacement", "los_velocity")}
        out["los"] = np.asarray(nc.attrs["los_unit_vector_enu"], dtype=np.float64)
    for k in ("los_displacement", "los_velocity"):
        out[k] = np.where(out[k] == FILL, np.nan, out[k])
    return out


def insar_figure(run_dir: str) -> str | None:
    """``insar_los.png``: the last output time's LOS displacement (mm) and velocity (mm/yr); None without a
    raster."""
    path = os.path.join(run_dir, NC_NAME)
    if not os.path.exists(path):
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ..units import YEAR
    from .observers import format_time
    d = read_netcdf(path)
    dx = d["x"][1] - d["x"][0] if len(d["x"]) > 1 else 1.0
    dy = d["y"][1] - d["y"][0] if len(d["y"]) > 1 else 1.0
    extent = (d["x"][0] - dx / 2, d["x"][-1] + dx / 2, d["y"][0] - dy / 2, d["y"][-1] + dy / 2)
    panel = float(np.clip(4.5 * (extent[1] - extent[0]) / (extent[3] - extent[2]), 2.5, 8.0))    # map's aspect
    fig, axes = plt.subplots(1, 2, figsize=(2 * panel + 3.0, 4.8), constrained_layout=True)
    panels = ((d["los_displacement"][-1] * 1e3, "LOS displacement (mm)"),
              (d["los_velocity"][-1] * 1e3 * YEAR, "LOS velocity (mm/yr, since the previous output)"))
    for ax, (values, label) in zip(axes, panels):
        lim = float(np.nanmax(np.abs(values))) if np.isfinite(values).any() else 1.0
        im = ax.imshow(values, origin="lower", extent=extent, cmap="RdBu_r", vmin=-lim or -1, vmax=lim or 1)
        fig.colorbar(im, ax=ax, label=label)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
    e, n, u = d["los"]
    fig.suptitle(f"t = {format_time(d['time'][-1]).strip()}; LOS (e, n, u) = ({e:.3f}, {n:.3f}, {u:.3f}), "
                 "positive towards the satellite")
    out = os.path.join(run_dir, PNG_NAME)
    fig.savefig(out + ".tmp", dpi=120, format="png")
    plt.close(fig)
    os.replace(out + ".tmp", out)
    return out


class InsarObserver(Observer):
    """Observer of the time loop (pfault.run): the LOS raster at time 0 (or the times of the run a restart
    continues) and at every output time of a converged step."""

    def __init__(self, output: Any, raster: Raster | None, located: Located, los: np.ndarray) -> None:
        m = output.model
        self.output, self.comm = output, m.comm
        self.probe = PointProbe(m.comm, m.mesh, m.dofmap, located)
        self.series = InsarSeries(raster, los) if m.comm.rank == 0 else None
        self.started = False

    def step_done(self, result: Any) -> None:
        out = self.output
        if not self.started:
            run_on_root(self.comm, lambda: self.series.start(out.writer.dir, out.restart_dir, out.restart_step))
            self.started = True
        if not (result.output and result.record.converged):
            return
        u = self.probe.values(result.u_rel)
        run_on_root(self.comm, lambda: self.series.append(out.writer.dir, result.step, result.t, u))
