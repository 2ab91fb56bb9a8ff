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
surface, and ``step`` (the step number of each time). The figure ``insar_los.png`` (pfault.post.figures) maps the
last time's LOS displacement and velocity; the observer is pfault.io.observations.InsarObserver. A restart keeps the
times of the run it continues up to its checkpoint's step.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import __version__
from ..errors import InputError
from ..georef import cf_time_units
from ..paths import beside_scene
from .probes import Raster
from .rasters import add_grid_mapping

NC_NAME = "insar_los.nc"
FILL = -9999.0          # _FillValue of the pixels outside the land surface
# |los| within this of 1 is a unit vector whose direction cosines were rounded (to two decimals they are up to ~0.009
# off) and is normalised; a length further off is not the cosines of a direction (angles, a scaled vector) and is
# an error
UNIT_TOL = 0.01
EXAMPLE = "-0.61,-0.11,0.785"       # Sentinel-1 ascending, incidence about 38 degrees: west, a little south, up


@dataclass(frozen=True)
class InsarSettings:
    los: np.ndarray | None      # (3,) unit vector east, north, up from the ground to the satellite (None: the grid's)
    spacing: float | None       # pixel size (m); None: the mean edge length of the land surface's triangles
    grid: str = ""              # -pfault_insar_grid: an InSAR product whose pixels the raster takes ('' : none)


def read_insar_settings(reader: Any, scene_file: str = "") -> InsarSettings | None:
    """-pfault_insar_los, -pfault_insar_spacing and -pfault_insar_grid (every rank); None without a LOS vector
    or a product grid."""
    los = reader.get("pfault_insar_los")
    spacing = reader.get("pfault_insar_spacing")
    grid = beside_scene(reader.get("pfault_insar_grid"), scene_file)
    if grid:            # the product's pixels: -pfault_insar_spacing, if any, is not used
        v = np.array(los, dtype=np.float64) if los else None
        if v is not None:
            check_los(v)
        return InsarSettings(None if v is None else v / np.linalg.norm(v), None, grid)
    if not los:
        if spacing is not None:
            raise InputError(f"-pfault_insar_spacing {spacing:g}: no raster without -pfault_insar_los; give the "
                             f"line-of-sight vector (e.g. -pfault_insar_los {EXAMPLE}) or remove the spacing")
        return None
    v = np.array(los, dtype=np.float64)
    check_los(v)
    if spacing is not None and not spacing > 0:
        raise InputError(f"-pfault_insar_spacing {spacing:g}: the pixel size must be positive (m), e.g. 50*m")
    return InsarSettings(v / np.linalg.norm(v), spacing)


def check_los(v: np.ndarray) -> None:
    """The LOS vector is pfault's convention: the unit vector from the ground to the satellite (east, north, up),
    so its up component is positive (a satellite looks down), and its length is 1 (rounded cosines within
    UNIT_TOL are normalised)."""
    text = ",".join(f"{x:g}" for x in v)
    what = "the east, north, up components of the unit vector from the ground to the satellite"
    if len(v) != 3:
        raise InputError(f"-pfault_insar_los {text}: give three components e,n,u: {what} (e.g. {EXAMPLE})")
    if v[2] < 0:
        flipped = ",".join(f"{-x:g}" for x in v)
        raise InputError(f"-pfault_insar_los {text}: the up component is negative, a vector from the satellite "
                         f"into the ground; pfault takes {what} (up positive, LOS positive towards the satellite): "
                         f"give -pfault_insar_los {flipped}")
    if v[2] == 0:
        raise InputError(f"-pfault_insar_los {text}: the up component is 0 (a satellite looks down, u = cos of the "
                         f"incidence angle); give {what} (e.g. {EXAMPLE})")
    norm = float(np.linalg.norm(v))
    if abs(norm - 1.0) > UNIT_TOL:
        raise InputError(f"-pfault_insar_los {text}: not a unit vector (length {norm:.4g}; rounded direction "
                         f"cosines are within {UNIT_TOL:g} of 1 and pfault normalises them); give {what} (e.g. "
                         f"{EXAMPLE})")


def check_continuation(raster: Raster, los: np.ndarray, run_dir: str) -> dict[str, np.ndarray]:
    """A restart continues the LOS raster of the run in ``run_dir``: it has one, of the same pixels and LOS
    vector; returns its arrays (read_netcdf)."""
    path = os.path.join(run_dir, NC_NAME)
    if not os.path.exists(path):
        raise InputError(f"-pfault_insar_los: the run in -pfault_restart {run_dir} has no LOS raster ({NC_NAME}); "
                         "continue it without -pfault_insar_los, or run the scene from the start with it")
    old = read_netcdf(path)
    same = (np.array_equal(old["x"], raster.x) and np.array_equal(old["y"], raster.y)
            and np.shape(old["los"]) == np.shape(los) and np.allclose(old["los"], los, rtol=0, atol=1e-12))
    if not same:
        raise InputError(f"-pfault_insar_los: the LOS vector or the pixels differ from those of the run in "
                         f"-pfault_restart {run_dir}; give the -pfault_insar_los and -pfault_insar_spacing it had")
    return old


class InsarSeries:
    """The LOS raster of a run (rank 0): ``insar_los.nc`` made whole at the start (time 0, or the times of the run
    a restart continues), then one time appended in place per output time (the file is closed after each, so a
    reader sees every time written). The last map and its time are kept for the velocity."""

    def __init__(self, raster: Raster, los: np.ndarray, crs: Any = None, start: Any = None) -> None:
        self.raster, self.los = raster, los
        self.crs, self.start_date = crs, start      # the raster's CRS and the scene's start date (pfault.georef)
        self.last: tuple[float, np.ndarray] | None = None

    def start(self, directory: str, restart_dir: str | None, restart_step: int | None) -> None:
        if restart_dir:
            steps, times, maps = self._continue(restart_dir, int(restart_step or 0))
        else:
            steps, times, maps = [0], [0.0], np.where(self.raster.inside, 0.0, np.nan)[None]
        write_netcdf(os.path.join(directory, NC_NAME), self.raster, self.los, steps, times, maps, self.crs,
                     self.start_date)
        self.last = (float(times[-1]), maps[-1])

    def _continue(self, run_dir: str, last_step: int) -> tuple:
        old = check_continuation(self.raster, self.los, run_dir)
        keep = old["step"] <= last_step
        return old["step"][keep], old["time"][keep], old["los_displacement"][keep]

    def append(self, directory: str, step: int, t: float, u: np.ndarray) -> None:
        """``u`` (k, 3): the displacement at the pixels inside the land surface."""
        los = np.full(self.raster.inside.shape, np.nan)
        los[self.raster.inside] = u @ self.los if self.los.ndim == 1 else np.einsum("kc,kc->k", u, self.los)
        t_prev, prev = self.last
        append_netcdf(os.path.join(directory, NC_NAME), step, t, los, (los - prev) / (t - t_prev))
        self.last = (float(t), los)


def velocities(times: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """LOS velocity at each time since the previous one (NaN at the first)."""
    rate = np.full_like(maps, np.nan)
    if len(times) > 1:
        rate[1:] = (maps[1:] - maps[:-1]) / (times[1:] - times[:-1])[:, None, None]
    return rate


def write_netcdf(path: str, raster: Raster, los: np.ndarray, steps: Sequence[int], times: Sequence[float],
                 maps: np.ndarray, crs: Any = None, start: Any = None) -> None:
    """``insar_los.nc`` (CF-1.8, NetCDF-4 through h5netcdf) with the given times, written into ``path``.tmp and
    renamed; its time dimension is unlimited (``append_netcdf``). With ``crs`` (pyproj) the grid mapping
    ``spatial_ref`` places x, y; with ``start`` (the scene's start date) the times are CF dates; a per-pixel LOS
    ``los`` ((k, 3), the pixels inside) is written as ``los_east``, ``los_north``, ``los_up``."""
    import h5netcdf
    disp = np.asarray(maps, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    tmp = path + ".tmp"
    with h5netcdf.File(tmp, "w") as nc:
        nc.attrs.update({
            "Conventions": "CF-1.8", "title": "line-of-sight displacement of the land surface",
            "source": f"pfault {__version__}",
            **({"los_unit_vector_enu": los.astype(np.float64)} if los.ndim == 1 else {}),
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
        v.attrs.update({"units": cf_time_units(start), "long_name": "time from the start of the scene"})
        if start is not None:
            v.attrs.update({"calendar": "standard", "standard_name": "time"})
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
        _write_georef(nc, raster, los, crs)
    os.replace(tmp, path)


def _write_georef(nc: Any, raster: Raster, los: np.ndarray, crs: Any) -> None:
    """The grid mapping of ``crs`` (and the data variables' ``grid_mapping``), and a per-pixel LOS."""
    if crs is not None:
        add_grid_mapping(nc, crs)
        for name in ("los_displacement", "los_velocity"):
            nc.variables[name].attrs["grid_mapping"] = "spatial_ref"
    if los.ndim == 2:
        for k, name in enumerate(("los_east", "los_north", "los_up")):
            grid = np.full(raster.inside.shape, FILL)
            grid[raster.inside] = los[:, k]
            v = nc.create_variable(name, ("y", "x"), np.float64, data=grid, fillvalue=FILL)
            v.attrs["long_name"] = f"{name[4:]} component of the unit vector from the ground to the satellite"


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
        if "los_unit_vector_enu" in nc.attrs:
            out["los"] = np.asarray(nc.attrs["los_unit_vector_enu"], dtype=np.float64)
        else:       # per pixel (k, 3), the pixels inside
            inside = nc.variables["los_east"][()] != FILL
            out["los"] = np.column_stack([nc.variables[k][()][inside] for k in ("los_east", "los_north", "los_up")])
        if "spatial_ref" in nc.variables:
            out["grid_mapping"] = dict(nc.variables["spatial_ref"].attrs)
    for k in ("los_displacement", "los_velocity"):
        out[k] = np.where(out[k] == FILL, np.nan, out[k])
    return out


