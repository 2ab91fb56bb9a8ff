"""InSAR time series written from NumPy in the layouts pfault.io.insar_input reads, for tests and examples (as
pfault.tools.mf6_write is for MODFLOW files): OPERA DISP-S1's (NetCDF-4 through h5netcdf: ``displacement`` (time, y, x)
north first, ``spatial_ref`` with the CRS and GDAL's GeoTransform, CF ``time`` and ``reference_time``, optional
``los_east``, ``los_north``) and MintPy's ``timeseries.h5`` (``timeseries``, ``date``, REF_DATE, EPSG, X_FIRST ...)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from typing import Any

import h5py
import numpy as np

from ..io.rasters import add_grid_mapping

EPOCH = "seconds since 1970-01-01 00:00:00"


def _seconds(dates: Sequence[dt.datetime]) -> np.ndarray:
    base = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)
    return np.array([(d - base).total_seconds() for d in dates], dtype=np.float64)


def write_opera(path: str, x: np.ndarray, y: np.ndarray, crs: Any, dates: Sequence[dt.datetime],
                reference: Sequence[dt.datetime], values: np.ndarray, los: np.ndarray | None = None) -> str:
    """``values`` (nt, ny, nx) m on increasing pixel centres ``x``, ``y`` (written north first, as GDAL and OPERA
    do), NaN where there is none; ``reference``: one date, or one per date; ``los`` (ny, nx, 3) or None."""
    import h5netcdf
    values = np.asarray(values, dtype=np.float64)[:, ::-1]
    yd = np.asarray(y, dtype=np.float64)[::-1]
    dx, dy = float(x[1] - x[0]), float(y[1] - y[0])
    with h5netcdf.File(path, "w") as nc:
        nc.attrs.update({"Conventions": "CF-1.8", "title": "OPERA_L3_DISP-S1-like product (synthetic)"})
        nc.dimensions = {"time": len(dates), "y": len(yd), "x": len(x)}
        add_grid_mapping(nc, crs)
        nc.variables["spatial_ref"].attrs["GeoTransform"] = f"{x[0] - dx / 2} {dx} 0 {yd[0] + dy / 2} 0 {-dy}"
        for name, axis in (("x", x), ("y", yd)):
            v = nc.create_variable(name, (name,), np.float64, data=axis)
            v.attrs.update({"standard_name": f"projection_{name}_coordinate", "units": "m"})
        v = nc.create_variable("time", ("time",), np.float64, data=_seconds(dates))
        v.attrs.update({"units": EPOCH, "calendar": "standard", "long_name": "secondary acquisition time"})
        ref = _seconds(reference)
        v = nc.create_variable("reference_time", ("time",) if len(ref) > 1 else (), np.float64,
                               data=ref if len(ref) > 1 else ref[0])
        v.attrs.update({"units": EPOCH, "calendar": "standard", "long_name": "reference acquisition time"})
        v = nc.create_variable("displacement", ("time", "y", "x"), np.float32, data=values.astype(np.float32),
                               fillvalue=np.float32(np.nan))
        v.attrs.update({"units": "meters", "grid_mapping": "spatial_ref",
                        "long_name": "displacement in the line of sight, positive towards the satellite"})
        if los is not None:
            for k, name in enumerate(("los_east", "los_north")):
                v = nc.create_variable(name, ("y", "x"), np.float32, data=np.asarray(los)[::-1, :, k])
                v.attrs["grid_mapping"] = "spatial_ref"
    return path


def write_mintpy(path: str, x: np.ndarray, y: np.ndarray, epsg: int, dates: Sequence[dt.datetime],
                 reference: dt.datetime, values: np.ndarray) -> str:
    """MintPy's geocoded timeseries.h5: ``values`` (nt, ny, nx) m on increasing ``x``, ``y``, written north first."""
    dx, dy = float(x[1] - x[0]), float(y[1] - y[0])
    with h5py.File(path, "w") as f:
        f["timeseries"] = np.asarray(values, dtype=np.float32)[:, ::-1]
        f["date"] = np.array([d.strftime("%Y%m%d").encode() for d in dates])
        f.attrs.update({"FILE_TYPE": "timeseries", "REF_DATE": reference.strftime("%Y%m%d"), "EPSG": str(epsg),
                        "X_FIRST": str(x[0] - dx / 2), "Y_FIRST": str(y[-1] + dy / 2), "X_STEP": str(dx),
                        "Y_STEP": str(-dy), "LENGTH": str(len(y)), "WIDTH": str(len(x)), "UNIT": "m"})
    return path
