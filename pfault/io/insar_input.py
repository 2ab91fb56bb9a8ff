"""InSAR displacement time series as delivered: NASA OPERA's DISP-S1 layout (NetCDF-4) or MintPy's ``timeseries.h5``,
read with h5py, for ``-pfault_insar_grid`` (the run's LOS raster on the product's pixels) and ``python -m
pfault.calibrate --insar`` (the product's values as observations).

OPERA DISP-S1 (a granule, or granules stacked along time as opera-utils and xarray stack them):

- ``displacement`` (time, y, x), metres (``units`` meters or m), NaN (or its ``_FillValue``) where there is none;
  its ``grid_mapping`` names the CRS variable (``spatial_ref``: ``crs_wkt``/``spatial_ref``, CF parameters);
- ``x`` (nx), ``y`` (ny): pixel centres in that CRS (``y`` north first as GDAL writes; either order is read);
- ``time`` and ``reference_time``: CF times (``seconds since 2016-07-01 00:00:00``, ``days since ...``): the
  secondary dates and their reference date, one for the whole stack or one per date (ministacks);
- optional ``los_east``, ``los_north`` (y, x): the unit vector from the ground to the satellite (OPERA's static
  layers; up = sqrt(1 - e^2 - n^2)), and ``recommended_mask`` ((time,) y, x; 0: do not use).

MintPy (``timeseries.h5``): ``timeseries`` (date, y, x) in metres, ``date`` (YYYYMMDD), attributes ``REF_DATE``,
``EPSG`` (or ``UTM_ZONE``), ``X_FIRST``, ``Y_FIRST`` (the upper-left corner), ``X_STEP``, ``Y_STEP``.

``read_insar_product`` returns an ``InsarProduct`` with the axes increasing (values turned round with them), the
dates and reference dates as UTC datetimes, the LOS per pixel when the file has it, and NaN where a pixel has no
value (masked pixels too). What cannot be used is an InputError naming the file and the fix: no CRS (where the
scene has one), values whose shape is not the axes', an axis out of order, no reference date, no pixel with a value.
NaN pixels are skipped, never filled. This module does not import PETSc.
"""

from __future__ import annotations

import datetime as dt
import os
import re
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np

from ..errors import InputError
from ..georef import crs_from_cf
from ..paths import file_problem

UTC = dt.timezone.utc
EPOCH = dt.datetime(1970, 1, 1, tzinfo=UTC)
SECONDS = {"second": 1.0, "seconds": 1.0, "s": 1.0, "minute": 60.0, "minutes": 60.0, "hour": 3600.0,
           "hours": 3600.0, "day": 86400.0, "days": 86400.0}


@dataclass(frozen=True)
class InsarProduct:
    """A product's pixels and series: ``x`` (nx,), ``y`` (ny,) increasing pixel centres in ``crs`` (pyproj or None),
    ``dates`` (nt,) and ``reference`` (nt,) UTC datetimes, ``values`` (nt, ny, nx) m (NaN: none; None when only the
    grid was read), ``los`` (ny, nx, 3) or None."""
    path: str
    x: np.ndarray
    y: np.ndarray
    crs: Any
    dates: list
    reference: list
    values: np.ndarray | None
    los: np.ndarray | None


def _text(v: Any) -> str:
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.ndarray):
        return _text(v.item()) if v.size == 1 else " ".join(_text(a) for a in v.ravel())
    return str(v)


def cf_dates(values: np.ndarray, units: Any, where: str) -> list:
    """UTC datetimes of CF times (``<unit> since <date>``)."""
    m = re.match(r"\s*(\w+)\s+since\s+(.+)", _text(units) if units is not None else "")
    if not m or m.group(1).lower() not in SECONDS:
        raise InputError(f"{where}: its times have units '{_text(units) if units is not None else ''}', not CF's "
                         "'<seconds|days> since <date>'; give the times as CF dates")
    base = m.group(2).strip().replace(" ", "T", 1).rstrip("Z").split(".")[0]
    try:
        start = dt.datetime.fromisoformat(base)
    except ValueError:
        raise InputError(f"{where}: the time origin '{m.group(2)}' is not a date") from None
    start = start.replace(tzinfo=UTC) if start.tzinfo is None else start.astimezone(UTC)
    scale = SECONDS[m.group(1).lower()]
    return [start + dt.timedelta(seconds=float(v) * scale) for v in np.atleast_1d(values)]


def _increasing(axis: np.ndarray, name: str, where: str) -> bool:
    """Whether an axis increases (False: it decreases, and is turned round); an axis out of order is an error."""
    step = np.diff(axis)
    if len(axis) < 2 or np.all(step > 0):
        return True
    if np.all(step < 0):
        return False
    raise InputError(f"{where}: its {name} coordinates are not in order (neither increasing nor decreasing); give "
                     "a regular raster")


def read_insar_product(path: str, with_values: bool = True, option: str = "--insar") -> InsarProduct:
    """The product at ``path`` (module docstring); ``with_values`` False reads its grid, CRS and LOS only."""
    where = f"{option} {path}"
    problem = file_problem(path)
    if problem:
        raise InputError(f"{where}: {problem}; give an OPERA DISP-S1 NetCDF file or MintPy's timeseries.h5")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"{where}: not an HDF5/NetCDF-4 file ({exc}); give an OPERA DISP-S1 NetCDF file or "
                         "MintPy's timeseries.h5") from None
    with f:
        if "displacement" in f:
            return _opera(f, path, where, with_values)
        if "timeseries" in f:
            return _mintpy(f, path, where, with_values)
    raise InputError(f"{where}: neither OPERA's 'displacement' (time, y, x) nor MintPy's 'timeseries'; give a "
                     "displacement time series in one of those layouts (docs/calibration.md)")


def _opera(f: Any, path: str, where: str, with_values: bool) -> InsarProduct:
    var = f["displacement"]
    x, y = np.asarray(f["x"][()], float), np.asarray(f["y"][()], float)
    if var.ndim != 3 or var.shape[1:] != (len(y), len(x)):
        raise InputError(f"{where}: 'displacement' is {var.shape}, but (time, y, x) asks for (nt, {len(y)}, "
                         f"{len(x)}); give the displacement on its x, y pixels, one map per date")
    gm = _text(var.attrs.get("grid_mapping", "")).strip()
    crs = crs_from_cf(dict(f[gm].attrs), where) if gm and gm in f else None
    if "time" not in f:
        raise InputError(f"{where}: no 'time' variable: the dates of the maps are unknown")
    dates = cf_dates(f["time"][()], f["time"].attrs.get("units"), where)
    if len(dates) != var.shape[0]:
        raise InputError(f"{where}: {len(dates)} times for {var.shape[0]} maps of 'displacement'")
    if "reference_time" not in f:
        raise InputError(f"{where}: no 'reference_time': InSAR displacements are relative to a reference date, and "
                         "the product names none; add reference_time (the date the displacement is zero), one or "
                         "one per date")
    ref = cf_dates(f["reference_time"][()], f["reference_time"].attrs.get("units"), where)
    ref = ref * len(dates) if len(ref) == 1 else ref
    values = los = None
    if with_values:
        values = np.asarray(var[()], float) * _metres(var.attrs.get("units"), where)
        fill = var.attrs.get("_FillValue")
        if fill is not None and np.isfinite(np.asarray(fill, float)).all():
            values[values == float(np.asarray(fill).ravel()[0])] = np.nan
        if "recommended_mask" in f:
            mask = np.broadcast_to(np.asarray(f["recommended_mask"][()]), values.shape)
            values = np.where(mask == 0, np.nan, values)
    if "los_east" in f and "los_north" in f:
        e, n = np.asarray(f["los_east"][()], float), np.asarray(f["los_north"][()], float)
        los = np.stack([e, n, np.sqrt(np.clip(1.0 - e * e - n * n, 0.0, None))], axis=-1)
    return _oriented(path, where, x, y, crs, dates, ref, values, los)


def _mintpy(f: Any, path: str, where: str, with_values: bool) -> InsarProduct:
    from pyproj import CRS
    a = {k: _text(v) for k, v in f.attrs.items()}
    var = f["timeseries"]
    if var.ndim != 3:
        raise InputError(f"{where}: 'timeseries' is {var.shape}; MintPy's is (date, y, x)")
    nt, ny, nx = var.shape
    if "X_FIRST" not in a or "Y_FIRST" not in a:
        raise InputError(f"{where}: no X_FIRST/Y_FIRST: a radar-coordinate time series; geocode it first "
                         "(MintPy's geocode.py) so that its pixels have map coordinates")
    x = float(a["X_FIRST"]) + float(a["X_STEP"]) * (np.arange(nx) + 0.5)
    y = float(a["Y_FIRST"]) + float(a["Y_STEP"]) * (np.arange(ny) + 0.5)
    crs = None
    if a.get("EPSG"):
        crs = CRS.from_epsg(int(a["EPSG"]))
    elif a.get("UTM_ZONE"):
        zone = a["UTM_ZONE"].upper()
        crs = CRS.from_epsg((32600 if zone.endswith("N") else 32700) + int(zone.rstrip("NS")))
    dates = [dt.datetime.strptime(_text(d), "%Y%m%d").replace(tzinfo=UTC) for d in f["date"][()]]
    if len(dates) != nt:
        raise InputError(f"{where}: {len(dates)} dates for {nt} maps of 'timeseries'")
    if not a.get("REF_DATE"):
        raise InputError(f"{where}: no REF_DATE attribute: InSAR displacements are relative to a reference date, "
                         "and the file names none; set REF_DATE (YYYYMMDD), as MintPy's reference_date.py does")
    ref = [dt.datetime.strptime(a["REF_DATE"], "%Y%m%d").replace(tzinfo=UTC)] * nt
    values = np.asarray(var[()], float) if with_values else None
    return _oriented(path, where, x, y, crs, dates, ref, values, None)


def _metres(units: Any, where: str) -> float:
    unit = _text(units).strip().lower() if units is not None else "m"
    table = {"m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0, "cm": 0.01, "mm": 0.001}
    if unit not in table:
        raise InputError(f"{where}: 'displacement' is in '{unit}'; give it in m (or cm, mm)")
    return table[unit]


def _oriented(path, where, x, y, crs, dates, ref, values, los) -> InsarProduct:
    """The product with increasing axes, checked: dates in order, some value."""
    flip_x, flip_y = not _increasing(x, "x", where), not _increasing(y, "y", where)
    if flip_x:
        x = x[::-1]
        values = None if values is None else values[:, :, ::-1]
        los = None if los is None else los[:, ::-1]
    if flip_y:
        y = y[::-1]
        values = None if values is None else values[:, ::-1]
        los = None if los is None else los[::-1]
    if any(b <= a for a, b in zip(dates, dates[1:])):
        raise InputError(f"{where}: its dates are not increasing; give the maps in time order")
    if values is not None and not np.isfinite(values).any():
        raise InputError(f"{where}: no pixel has a value (all NaN or masked)")
    return InsarProduct(os.path.abspath(path), x, y, crs, list(dates), list(ref), values, los)
