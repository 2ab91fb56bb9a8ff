"""MODFLOW 6 NetCDF heads read in-process (pfault.sources.netcdf_heads): a file in another CRS than the scene's is
looked up at the centroids reprojected by pyproj (checked cell by cell against pyproj's transformation and the
grid's edges); a file whose y increases gives the same heads as MODFLOW's north-first order; a file without a CRS
is taken in the scene's coordinates; every bad form is one line naming the file and the fix."""

import h5py
import numpy as np
import pytest
from pyproj import CRS, Transformer

from pfault.errors import InputError
from pfault.sources.heads import HeadsSettings
from pfault.sources.netcdf_heads import Reprojected, open_mf6_netcdf
from pfault.tools.mf6_netcdf_write import mesh, structured

UTM = CRS.from_epsg(32650)           # the scene's: WGS 84 / UTM zone 50N
GK = CRS.from_epsg(4547)             # the model's: CGCS2000 / 3-degree Gauss-Kruger CM 114E
NCOL, NROW, CELL = 40, 30, 100.0


def settings(path, crs=UTM, grid=""):
    return HeadsSettings(file=str(path), grid=grid, time_unit=86400.0, time_unit_given=False, length_unit=1.0,
                         reference_time=None, outside="error", origin=(0.0, 0.0, 0.0), water_density=1000.0,
                         gravity=9.80665, crs=crs)


def model_file(tmp_path, crs=GK, flip_y=False, name="gk.nc"):
    """A 40 x 30 grid of 100 m cells in the model's CRS around (500000, 3500000) there; heads at time 1 are
    cell-wise distinct (100 + column + 1000 row)."""
    col, row = np.meshgrid(np.arange(NCOL), np.arange(NROW))
    h1 = 100.0 + col + 1000.0 * row
    heads = np.stack([np.full((1, NROW, NCOL), 100.0), h1[None]])
    top, botm = np.full((NROW, NCOL), 10.0), np.full((1, NROW, NCOL), -50.0)
    return structured(str(tmp_path / name), [0.0, 1.0], heads, 498000.0, 3498500.0, [CELL] * NCOL, [CELL] * NROW,
                      top, botm, crs=crs, flip_y=flip_y)


def test_other_crs_is_reprojected_as_pyproj_does(tmp_path):
    heads, grid = open_mf6_netcdf(settings(model_file(tmp_path)))
    assert isinstance(grid, Reprojected)
    rng = np.random.default_rng(3)
    # points in the scene's CRS that fall inside the model: the model's points moved into UTM by pyproj
    gx, gy = 498000.0 + rng.uniform(50, NCOL * CELL - 50, 200), 3498500.0 + rng.uniform(50, NROW * CELL - 50, 200)
    ux, uy = Transformer.from_crs(GK, UTM, always_xy=True).transform(gx, gy)
    assert np.hypot(ux - gx, uy - gy).min() > 1e5       # 3 degrees of longitude apart: no coordinate is alike
    cells = grid.cells(np.column_stack([ux, uy, np.zeros(200)]))
    back = Transformer.from_crs(UTM, GK, always_xy=True).transform(ux, uy)
    col = np.floor((back[0] - 498000.0) / CELL).astype(int)
    row = NROW - 1 - np.floor((back[1] - 3498500.0) / CELL).astype(int)
    assert np.array_equal(cells, row * NCOL + col)
    assert np.array_equal(heads.values(1)[cells], 100.0 + col + 1000.0 * row)
    lo, hi = grid.extent()                               # for messages, in the scene's CRS
    assert lo[0] < ux.min() and hi[0] > ux.max() and lo[2] == -50.0 and hi[2] == 10.0
    heads.close()


def test_same_crs_or_none_is_not_reprojected_and_y_order_does_not_matter(tmp_path):
    a, grid_a = open_mf6_netcdf(settings(model_file(tmp_path, crs=UTM), crs=UTM))
    b, grid_b = open_mf6_netcdf(settings(model_file(tmp_path, crs=None, flip_y=True, name="up.nc"), crs=UTM))
    assert not isinstance(grid_a, Reprojected) and not isinstance(grid_b, Reprojected) and b.crs is None
    pts = np.column_stack([np.linspace(498010, 501990, 50), np.linspace(3498510, 3501490, 50), np.zeros(50)])
    assert np.array_equal(grid_a.cells(pts), grid_b.cells(pts))
    assert np.array_equal(a.values(1), b.values(1)) and np.array_equal(grid_a.botm, grid_b.botm)
    a.close()
    b.close()


def test_mesh_in_other_crs(tmp_path):
    x, y = np.meshgrid(498000.0 + CELL * np.arange(3), 3498500.0 + CELL * np.arange(3))
    verts = np.column_stack([x.ravel(), y.ravel()])
    faces = [[j * 3 + i, j * 3 + i + 1, (j + 1) * 3 + i + 1, (j + 1) * 3 + i] for j in range(2) for i in range(2)]
    path = mesh(str(tmp_path / "m.nc"), [0.0, 1.0], np.arange(8.0).reshape(2, 1, 4), verts, faces,
                np.full(4, 10.0), np.full((1, 4), -50.0), crs=GK)
    heads, grid = open_mf6_netcdf(settings(path))
    centres = verts[np.array(faces)].mean(axis=1)
    ux, uy = Transformer.from_crs(GK, UTM, always_xy=True).transform(centres[:, 0], centres[:, 1])
    assert np.array_equal(grid.cells(np.column_stack([ux, uy, np.zeros(4)])), np.arange(4))
    assert np.array_equal(heads.values(1), [4.0, 5.0, 6.0, 7.0])
    heads.close()


def edit(path, fn):
    with h5py.File(path, "r+") as f:
        fn(f)
    return path


@pytest.mark.parametrize("change,words", [
    (lambda f: [f.__delitem__(k) for k in ("dis_top", "dis_botm")], "holds no layer elevations (TOP, BOTM); export "
     "them from the model (EXPORT_ARRAY_NETCDF in its DIS/DISV package) or give the model's binary grid file"),
    (lambda f: f["head"].attrs.__setitem__("grid_mapping", "nowhere"), "its grid_mapping 'nowhere' names no variable"),
    (lambda f: f["time"].__setitem__(slice(None), [1.0, 0.0]), "its saved times are empty, not finite or not increasing"),
    (lambda f: f.__delitem__("head"), "has no 'head' variable"),
    (lambda f: f["projection"].attrs.__setitem__("crs_wkt", "PROJCS[nonsense"), "is not a WKT PROJ reads"),
])
def test_bad_files_are_one_line(tmp_path, change, words):
    path = edit(model_file(tmp_path), change)
    with pytest.raises(InputError) as err:
        open_mf6_netcdf(settings(path))
    line = str(err.value)
    assert "\n" not in line and line.startswith(f"-pfault_heads_file {path}") and words in line, line


def test_wrong_shape_and_nan(tmp_path):
    heads = np.full((2, 1, NROW, NCOL), 100.0)
    top, botm = np.full((NROW, NCOL), 10.0), np.full((1, NROW, NCOL), -50.0)
    path = structured(str(tmp_path / "nan.nc"), [0.0, 1.0], heads, 0.0, 0.0, [CELL] * NCOL, [CELL] * NROW, top, botm)
    # (xarray writes a NaN as the _FillValue, 1e30: an inactive cell; a NaN in the file is another writer's)
    edit(path, lambda f: f["head"].__setitem__((1, 0, 3, 4), np.nan))
    reader, _ = open_mf6_netcdf(settings(path, crs=None))
    with pytest.raises(InputError, match="1 heads are NaN at time 1; MODFLOW writes dry cells as -1e30"):
        reader.values(1)
    reader.close()
    edit(path, lambda f: f["x"].__setitem__(slice(None), np.r_[f["x"][:-1], 0.0]))
    with pytest.raises(InputError, match="coordinate 'x' is not in order"):
        open_mf6_netcdf(settings(path, crs=None))
    bad = str(tmp_path / "shape.nc")
    structured(bad, [0.0, 1.0], heads[:, :, :, :-1], 0.0, 0.0, [CELL] * (NCOL - 1), [CELL] * NROW, top[:, :-1],
               botm[:, :, :-1])
    edit(bad, lambda f: f.__delitem__("time") or f.create_dataset("time", data=[0.0, 1.0, 2.0]))
    with pytest.raises(InputError, match=r"'head' is \(2, 1, 30, 39\), but time, z, y, x ask for"):
        open_mf6_netcdf(settings(bad, crs=None))
