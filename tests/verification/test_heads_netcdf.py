"""MODFLOW 6 NetCDF heads (pfault.sources.netcdf_heads), written with xarray as MODFLOW 6 writes them
(tests/mf6_netcdf.py): the oedometer column of tests/verification/test_heads.py settles c_M rho_w g Dh H =
0.326888333 m to 1e-8 at every step, as through the binary files, from a structured file (its layer elevations
exported), a UGRID layered mesh, and a structured file without elevations beside the model's binary grid file;
the scene's CRS is the file's, and the subsidence GeoTIFF (gis/) holds the settlement at every pixel."""

import numpy as np
import pytest
from pyproj import CRS

from pfault.tools.mf6_netcdf_write import mesh, structured
from test_heads import BOTTOMS, EXACT, ORIGIN, assert_column, column, column_heads, dis_files

UTM = CRS.from_epsg(32650)


def layered(shape):
    top = np.full(shape, 20.0)
    return top, np.stack([np.full(shape, b) for b in BOTTOMS])


def structured_file(tmp_path, elevations=True):
    heads = np.broadcast_to(column_heads()[:, :, None, None], (2, 3, 2, 2))
    top, botm = layered((2, 2)) if elevations else (None, None)
    path = structured(str(tmp_path / "col.nc"), [0.0, 10.0], heads, ORIGIN[0], ORIGIN[1], [5.0, 5.0], [5.0, 5.0],
                      top, botm, crs=UTM)
    return ["-pfault_heads_file", path]


def mesh_file(tmp_path):
    """Four quadrilaterals over the column (10 m x 10 m), counter-clockwise, in world coordinates."""
    xs, ys = ORIGIN[0] + np.array([0.0, 5.0, 10.0]), ORIGIN[1] + np.array([0.0, 5.0, 10.0])
    verts = np.array([(x, y) for y in ys for x in xs])
    faces = [[j * 3 + i, j * 3 + i + 1, (j + 1) * 3 + i + 1, (j + 1) * 3 + i] for j in range(2) for i in range(2)]
    heads = np.broadcast_to(column_heads()[:, :, None], (2, 3, 4))
    top, botm = layered(4)
    return ["-pfault_heads_file", mesh(str(tmp_path / "colm.nc"), [0.0, 10.0], heads, verts, faces, top, botm,
                                      crs=UTM)]


@pytest.mark.parametrize("layout", ["structured", "mesh", "structured_grb"])
def test_oedometer_settlement_through_modflow_netcdf_heads(tmp_path, layout):
    if layout == "structured":
        files = structured_file(tmp_path)
    elif layout == "mesh":
        files = mesh_file(tmp_path)
    else:
        files = structured_file(tmp_path, elevations=False) + dis_files(tmp_path)[2:]     # the .dis.grb
    files += ["-pfault_crs", "EPSG:32650", "-pfault_map_spacing", "2.5"]
    proc, summary = column(tmp_path, files)
    assert "groundwater-model heads" in proc.stdout
    assert_column(summary)
    if layout == "structured":
        from osgeo import gdal
        a = gdal.Open(str(tmp_path / "out1" / "gis" / "subsidence.tif")).ReadAsArray()
        assert a.shape == (4, 4) and np.allclose(a, EXACT, rtol=1e-8)


def test_site_example_netcdf_heads_in_their_own_crs_equal_the_binary_files(tmp_path):
    """config/site_example: site.nc (a layered mesh in CGCS2000 Gauss-Kruger, reprojected into the scene's UTM zone)
    gives the run of site.hds + site.dis.grb (the same model in site coordinates) to round-off."""
    from conftest import compare_runs, run_scene
    _, nc = run_scene("config/site_example/site.opts", tmp_path / "nc")
    _, binary = run_scene("config/site_example/site.opts", tmp_path / "bin", extra=[
        "-pfault_heads_file", "config/site_example/site.hds", "-pfault_heads_grid", "config/site_example/site.dis.grb",
        "-pfault_heads_time_unit", "day"])
    assert nc["max_subsidence_m"] == pytest.approx(1.28872, abs=1e-5)
    assert compare_runs(tmp_path / "nc", tmp_path / "bin", 1e-12) < 1e-12
