"""Writes the MODFLOW 6 files of the example site from NumPy: the binary grid and head files (site.dis.grb, site.hds)
and the same heads as MODFLOW 6's NetCDF output (site.nc: a UGRID layered mesh with its CRS).

MODFLOW 6 itself is not needed: pfault.tools.mf6_write writes the binary grid and head files in the layouts of the
MODFLOW 6 input/output guide, and flopy reads them as it reads MODFLOW's own; pfault.tools.mf6_netcdf_write writes the
NetCDF file with xarray as MODFLOW 6's NETCDF_MESH2D output does. The model:

- DIS grid of 30 columns x 20 rows of 100 m, rotated 20 degrees counter-clockwise about its lower-left corner,
  which sits so that the grid's centre is the mesh's centre at site (501000, 3500500); three layers: a clay
  aquitard from the land surface (5 m above datum) to -25 m, and a sand aquifer in two layers down to -85 m and
  -145 m (the layer bottoms are node planes of the mesh in site.opts);
- TDIS in days: a steady-state first period of one day (heads at rest, 3 m above datum), then ten years of
  pumping saved once a year;
- a well in the aquifer at site (501300, 3500600) lowers its heads by S(t) ln(R/r) / ln(R/r_w) (R = 3 km,
  r_w = 50 m, S growing linearly to 30 m in ten years); the clay above follows with half of it;
- site coordinates are WGS 84 / UTM zone 50N (EPSG:32650, the scene's -pfault_crs); the groundwater model's own CRS
  is CGCS2000 / 3-degree Gauss-Kruger CM 114E (EPSG:4547), in which site.nc gives its cells' corners (pyproj), so
  that the run reprojects them; its times are days since 2015-01-01, the scene's -pfault_start_date.

Run from the repository: python config/site_example/make_heads.py
"""

import os

import numpy as np

from pyproj import CRS, Transformer

from pfault.tools.mf6_netcdf_write import mesh
from pfault.tools.mf6_write import write_dis_grb, write_heads

HERE = os.path.dirname(os.path.abspath(__file__))
NCOL, NROW, CELL = 30, 20, 100.0
ANGROT = 20.0
CENTRE = np.array([501000.0, 3500500.0])
WELL = np.array([501300.0, 3500600.0])
LAND, BOTTOMS = 5.0, (-25.0, -85.0, -145.0)
REST_HEAD = 3.0
MAX_DRAWDOWN, R_OUTER, R_WELL = 30.0, 3000.0, 50.0
YEAR_DAYS = 365.25
SITE_CRS, MODEL_CRS = 32650, 4547


def rotate(v, degrees):
    a = np.deg2rad(degrees)
    return np.stack([v[..., 0] * np.cos(a) - v[..., 1] * np.sin(a), v[..., 0] * np.sin(a) + v[..., 1] * np.cos(a)],
                    axis=-1)


def main():
    origin = CENTRE - rotate(np.array([NCOL * CELL / 2, NROW * CELL / 2]), ANGROT)
    top = np.full((NROW, NCOL), LAND)
    botm = np.stack([np.full((NROW, NCOL), b) for b in BOTTOMS])
    write_dis_grb(os.path.join(HERE, "site.dis.grb"), np.full(NCOL, CELL), np.full(NROW, CELL), top, botm,
                  xorigin=origin[0], yorigin=origin[1], angrot=ANGROT)
    # cell centres in site coordinates (row 0 at the top edge of the grid)
    local = np.stack(np.meshgrid((np.arange(NCOL) + 0.5) * CELL, (NROW - np.arange(NROW) - 0.5) * CELL), axis=-1)
    centres = rotate(local, ANGROT) + origin
    r = np.maximum(np.linalg.norm(centres - WELL, axis=-1), R_WELL)
    shape = np.clip(np.log(R_OUTER / r) / np.log(R_OUTER / R_WELL), 0.0, 1.0)
    times = np.concatenate([[1.0], 1.0 + YEAR_DAYS * np.arange(1, 11)])
    heads = []
    for t in times:
        s = MAX_DRAWDOWN * (t - 1.0) / (10 * YEAR_DAYS) * shape
        heads.append(np.stack([REST_HEAD - 0.5 * s, REST_HEAD - s, REST_HEAD - s]))
    write_heads(os.path.join(HERE, "site.hds"), times, np.array(heads), kper=[1] + [2] * 10)
    write_netcdf(origin, times, np.array(heads), top, botm)


def write_netcdf(origin, times, heads, top, botm):
    """site.nc: the cells as a UGRID layered mesh (counter-clockwise corners, rows from the north as MODFLOW's), in
    the model's CRS."""
    i, j = np.meshgrid(np.arange(NCOL + 1), np.arange(NROW + 1))           # corner (column, row from the north)
    corners = rotate(np.stack([i * CELL, (NROW - j) * CELL], axis=-1).astype(float), ANGROT) + origin
    x, y = Transformer.from_crs(CRS.from_epsg(SITE_CRS), CRS.from_epsg(MODEL_CRS), always_xy=True).transform(
        corners[..., 0].ravel(), corners[..., 1].ravel())
    node = np.arange((NROW + 1) * (NCOL + 1)).reshape(NROW + 1, NCOL + 1)
    faces = np.stack([node[1:, :-1], node[1:, 1:], node[:-1, 1:], node[:-1, :-1]], axis=-1).reshape(-1, 4)
    mesh(os.path.join(HERE, "site.nc"), times, heads.reshape(len(times), 3, -1), np.column_stack([x, y]), faces,
         top.ravel(), botm.reshape(3, -1), crs=CRS.from_epsg(MODEL_CRS), time_units="days since 2015-01-01T00:00:00")


if __name__ == "__main__":
    main()
