"""Rasters on disk in a CRS: a one-band GeoTIFF (rasterio) and the CF grid mapping of a NetCDF file (h5netcdf), as
the LOS raster (pfault.io.insar), the GIS layers of a run (pfault.post.gis) and the calibration's InSAR residuals
(pfault.tools.insar_report) write them."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..georef import cf_grid_mapping


def write_geotiff(path: str, x: np.ndarray, y: np.ndarray, values: np.ndarray, crs: Any,
                  tags: dict | None = None) -> str:
    """A one-band float64 GeoTIFF of ``values`` (ny, nx) on pixel centres ``x``, ``y`` (regular, ascending; written
    north up), NaN no-data, in ``crs`` (pyproj); ``tags``: metadata of the band (units, time)."""
    import rasterio
    from affine import Affine
    dx = float(x[1] - x[0]) if len(x) > 1 else 1.0
    dy = float(y[1] - y[0]) if len(y) > 1 else dx
    transform = Affine(dx, 0.0, float(x[0]) - dx / 2, 0.0, -dy, float(y[-1]) + dy / 2)
    tmp = path + ".tmp.tif"
    with rasterio.open(tmp, "w", driver="GTiff", width=len(x), height=len(y), count=1, dtype="float64",
                       crs=rasterio.crs.CRS.from_wkt(crs.to_wkt()), transform=transform, nodata=np.nan,
                       compress="deflate") as dst:
        dst.write(np.asarray(values, dtype=np.float64)[::-1], 1)
        if tags:
            dst.update_tags(1, **{k: str(v) for k, v in tags.items()})
            dst.set_band_description(1, str(tags.get("long_name", "")))
    os.replace(tmp, path)
    return path


def add_grid_mapping(nc: Any, crs: Any, name: str = "spatial_ref") -> None:
    """The CF grid-mapping variable ``name`` of ``crs`` in an open h5netcdf file (a scalar int holding the CRS in
    its attributes; pfault.georef.cf_grid_mapping)."""
    v = nc.create_variable(name, (), np.int32, data=np.int32(0))
    v.attrs.update(cf_grid_mapping(crs))
