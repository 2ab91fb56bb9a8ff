"""Spatial material fields (pfault.materials.properties, pfault.materials.field_files): formats, interpolation,
checks.

The bilinear values are computed by hand from the map's four corners around each point; scattered points
reproduce a linear function exactly; the same grid in CSV, HDF5 and NetCDF gives the same values.
"""

import h5py
import numpy as np
import pytest

from pfault.errors import InputError
from pfault.materials import properties as pr
from pfault.materials.field_files import read_field
from pfault.mesh.box import box_mesh
from pfault.paths import beside_scene
from pfault.scene import Material

OPTION = "pfault_material_clay_young_modulus"

# a clay modulus map E(x, y) in MPa on the grid x = 0, 100, 300 and y = 0, 200
MAP_X = [0.0, 100.0, 300.0]
MAP_Y = [0.0, 200.0]
MAP_E = {(0, 0): 4.0, (1, 0): 8.0, (2, 0): 6.0, (0, 1): 10.0, (1, 1): 12.0, (2, 1): 20.0}   # (ix, iy) -> MPa


def write_map_csv(path, unit="MPa", order=None):
    rows = [(MAP_X[i], MAP_Y[j], MAP_E[i, j]) for (i, j) in (order or sorted(MAP_E))]
    path.write_text(f"# clay modulus map\nx,y,young_modulus [{unit}]\n" + "".join(f"{x},{y},{e}\n" for x, y, e in rows))
    return str(path)


def ref(path, **kw):
    return pr.FieldRef(OPTION, str(path), unit="Pa", **kw)


def test_map_is_bilinear_by_hand(tmp_path):
    """At (50, 50): in the cell x 0..100, y 0..200 with weights (1/2, 1/4): corners 4, 8 (y = 0) and 10, 12
    (y = 200): 3/4 (4+8)/2 + 1/4 (10+12)/2 = 4.5 + 2.75 = 7.25 MPa. At (250, 150): cell x 100..300 (weight 3/4
    towards 300), y weight 3/4: y = 0: 8 + 3/4 (6-8) = 6.5; y = 200: 12 + 3/4 (20-12) = 18; 6.5 + 3/4 (18-6.5) =
    15.125 MPa. At a grid node (100, 200): 12 MPa; on an edge (200, 0): (8+6)/2 = 7 MPa."""
    field = read_field(write_map_csv(tmp_path / "map.csv", order=sorted(MAP_E, reverse=True)), OPTION, "Pa")
    assert field.is_grid and field.names == ("x", "y")
    pts = np.array([[50.0, 50.0, -3.0], [250.0, 150.0, -40.0], [100.0, 200.0, 0.0], [200.0, 0.0, -1.0]])
    values, outside = pr.interpolate(field, pts)
    assert not outside.any()
    assert values == pytest.approx(np.array([7.25, 15.125, 12.0, 7.0]) * 1e6, rel=1e-14)


def test_map_at_cell_centroids_of_a_box(tmp_path):
    """The map at the centroids of a box mesh's cells (the model's serial evaluation) equals the bilinear formula
    written out at each centroid; z plays no part in a 2-D map."""
    mesh = box_mesh((300.0, 200.0, 30.0), (3, 2, 2), materials=("clay",))
    mats = [Material("clay", ref(write_map_csv(tmp_path / "map.csv")), 0.3, 1.0, 2000.0)]
    values = pr.serial_field_values(["clay"], pr.field_refs(mats), mesh.points, mesh.tets, mesh.cell_material, "")
    c = mesh.points[mesh.tets].mean(axis=1)
    x, y = c[:, 0], c[:, 1]
    i = np.where(x < 100.0, 0, 1)
    x0, x1 = np.array(MAP_X)[i], np.array(MAP_X)[i + 1]
    tx, ty = (x - x0) / (x1 - x0), y / 200.0
    e = np.array([[MAP_E[k, j] for j in (0, 1)] for k in range(3)]) * 1e6     # [ix, iy]
    hand = ((1 - tx) * (1 - ty) * e[i, 0] + tx * (1 - ty) * e[i + 1, 0] + (1 - tx) * ty * e[i, 1]
            + tx * ty * e[i + 1, 1])
    assert values[OPTION] == pytest.approx(hand, rel=1e-13)
    props = pr.CellProperties.of_cells(mats, mesh.cell_material, values)
    assert np.array_equal(props.young_modulus, values[OPTION])
    assert np.all(props.poisson_ratio == 0.3) and np.all(props.density == 2000.0)


def test_same_grid_in_hdf5_netcdf_and_csv(tmp_path):
    """CF layout (y, x), x fastest, with a units attribute; classic NetCDF through scipy; a 3-D grid too."""
    from scipy.io import netcdf_file
    e = np.array([[MAP_E[i, j] for i in range(3)] for j in range(2)])        # (ny, nx) MPa
    with h5py.File(tmp_path / "map.h5", "w") as h5:
        h5["x"], h5["y"] = MAP_X, MAP_Y
        h5["E"] = e * 1e3
        h5["E"].attrs["units"] = "kPa"
    nc = netcdf_file(str(tmp_path / "map.nc"), "w")
    nc.createDimension("x", 3)
    nc.createDimension("y", 2)
    for name, dims, data in (("x", ("x",), MAP_X), ("y", ("y",), MAP_Y), ("young_modulus", ("x", "y"), e.T)):
        v = nc.createVariable(name, "d", dims)
        v[:] = data
    nc.variables["young_modulus"].units = "MPa"
    nc.close()
    pts = np.array([[50.0, 50.0, 0.0], [250.0, 150.0, 0.0], [299.0, 1.0, 0.0]])
    ref_values = pr.interpolate(read_field(write_map_csv(tmp_path / "map.csv"), OPTION, "Pa"), pts)[0]
    for name in ("map.h5", "map.nc"):
        field = read_field(str(tmp_path / name), OPTION, "Pa", default_variable="young_modulus")
        assert pr.interpolate(field, pts)[0] == pytest.approx(ref_values, rel=1e-14), name
    # NetCDF-4 as the netCDF library writes it (HDF5 dimension scales): a variable stored (x, y) by its dimensions
    with h5py.File(tmp_path / "map4.nc", "w") as h5:
        h5["x"], h5["y"] = MAP_X, MAP_Y
        h5["x"].make_scale("x")
        h5["y"].make_scale("y")
        h5["young_modulus"] = e.T * 1e6
        h5["young_modulus"].dims[0].attach_scale(h5["x"])
        h5["young_modulus"].dims[1].attach_scale(h5["y"])
    field = read_field(str(tmp_path / "map4.nc"), OPTION, "Pa")
    assert pr.interpolate(field, pts)[0] == pytest.approx(ref_values, rel=1e-14)
    # 3-D grid (z, y, x) varying in z only
    with h5py.File(tmp_path / "cube.h5", "w") as h5:
        h5["x"], h5["y"], h5["z"] = [0.0, 10.0], [0.0, 10.0], [-100.0, 0.0]
        h5["young_modulus"] = np.array([1e6, 3e6])[:, None, None] * np.ones((2, 2, 2))
    field = read_field(str(tmp_path / "cube.h5"), OPTION, "Pa")
    assert pr.interpolate(field, np.array([[3.0, 7.0, -25.0]]))[0] == pytest.approx([2.5e6], rel=1e-14)


def test_scattered_points_reproduce_a_linear_field(tmp_path):
    rng = np.random.default_rng(3)
    p = np.vstack([[[0, 0], [1000, 0], [0, 1000], [1000, 1000]], rng.uniform(0, 1000, (20, 2))])
    f = lambda x, y: 5e6 + 2e3 * x - 1e3 * y     # noqa: E731
    (tmp_path / "pts.csv").write_text("x,y,E\n" + "".join(f"{x!r},{y!r},{f(x, y)!r}\n" for x, y in p))
    field = read_field(str(tmp_path / "pts.csv"), OPTION, "Pa")
    assert not field.is_grid
    q = np.column_stack([rng.uniform(0, 1000, (50, 2)), np.zeros(50)])
    values, outside = pr.interpolate(field, q)
    assert not outside.any()
    assert values == pytest.approx(f(q[:, 0], q[:, 1]), rel=1e-12)


def test_outside_is_an_error_unless_nearest(tmp_path):
    mesh = box_mesh((400.0, 200.0, 30.0), (4, 2, 1), materials=("clay",))     # x beyond the map's 300 m
    path = write_map_csv(tmp_path / "map.csv")
    for outside in ("error", "nearest"):
        mats = [Material("clay", ref(path, outside=outside), 0.3, 1.0, 2000.0)]
        args = (["clay"], pr.field_refs(mats), mesh.points, mesh.tets, mesh.cell_material, "")
        if outside == "error":
            with pytest.raises(InputError, match=r"field:.*map.csv: 12 of 48 cells of 'clay' lie outside the field "
                                                 r"\(their centroids at x 325..375, y 25..175 m; the "
                                                 r"field spans x 0..300 m, y 0..200 m\); extend.*add ,outside=nearest"):
                pr.serial_field_values(*args)
        else:
            values = pr.serial_field_values(*args)[OPTION]
            c = mesh.points[mesh.tets].mean(axis=1)
            beyond = c[:, 0] > 300.0
            expect = pr.interpolate(read_field(path, OPTION, "Pa"), np.column_stack([np.full(beyond.sum(), 300.0),
                                                                                     c[beyond, 1:]]))[0]
            assert values[beyond] == pytest.approx(expect, rel=1e-14)


GRID_2X2 = "0,0,1e6\n1,0,1e6\n0,1,1e6\n1,1,1e6\n"

# each bad CSV file and the message after its "-OPTION field:PATH": the cause (with the line) and the fix
BAD_CSV = [
    ("x,y,E\n0,0,1e6\n1,0,nan\n0,1,1e6\n1,1,1e6\n", "young_modulus",
     ": 1 of 4 E are NaN or infinite (line 3); fill them (or remove those points) and run again"),
    ("x,y,E\n0,0,1e6\n1,0,inf\n0,1,-inf\n1,1,1e6\n", "young_modulus",
     ": 2 of 4 E are NaN or infinite (lines 3, 4); fill them (or remove those points) and run again"),
    ("x,y,E\n0,0,1e6\nnan,0,1e6\n0,1,1e6\n1,1,1e6\n", "young_modulus",
     ": 1 of 4 x coordinates are NaN or infinite (line 3); fill them (or remove those points) and run again"),
    ("x,y,E\n0,0,1e6\n1,0,-2e6\n0,1,1e6\n1,1,1e6\n", "young_modulus",
     ": 1 values are not positive (e.g. -2e+06); fix the file's values (in the option's unit unless the file states "
     "its own)"),
    ("z,nu\n-10,0.3\n0,0.5\n", "poisson_ratio", ": 1 values are not in (-1, 0.5) (e.g. 0.5); fix the file's values "
     "(in the option's unit unless the file states its own)"),
    ("x,y,E [m]\n" + GRID_2X2, "young_modulus", ": 'E' is in m, a length, but the option takes a pressure in Pa; give "
     "the variable in that unit"),
    ("x,y,E [psi]\n" + GRID_2X2, "young_modulus", ": unknown unit 'psi' of 'E'; give a unit such as Pa (pressure)"),
    ("x,y,E,F\n0,0,1,1\n1,0,1,1\n0,1,1,1\n1,1,1,1\n", "young_modulus", ": 2 candidate variables (E, F); name one "
     "with ,variable=NAME after the path"),
    # the columns: named, unknown, only coordinates, twice, not separated by commas, no header
    ("a,b,E\n0,0,1\n", "young_modulus", ": no coordinate named x, y or z (its columns: a, b, E); name the coordinate "
     "columns x, y and/or z (m, site coordinates)"),
    ("x,y\n0,0\n1,0\n0,1\n1,1\n", "young_modulus", ": the file has only coordinate columns (x, y) and no value; add "
     "the value's column (e.g. x,y,young_modulus [unit])"),
    ("x,x,E\n0,0,1\n1,1,2\n", "young_modulus", ": column 'x' is named twice in the header (columns 1 and 2); name "
     "each column once"),
    ("x;y;E\n0;0;1\n", "young_modulus", ": the header line 'x;y;E' is one column; separate the columns with commas"),
    ("0,0,1\n1,0,2\n", "young_modulus", ": the first line (0, 0, 1) is numbers, not a header; add a line naming the "
     "columns first, e.g. x,y,value [unit]"),
    ("# only a header\nx,y,E\n", "young_modulus", ": needs a header line (x,y,value ...) and at least one line of "
     "values"),
    # a line missing its value, an empty value, a word, one value too many (line numbers count comments)
    ("# map\nx,y,E\n0,0,1\n1,0\n0,1,1\n1,1,1\n", "young_modulus", " line 4: no value for E (the line has 2 of the 3 "
     "columns x, y, E); give a number in every column or remove the line"),
    ("x,y,E\n0,0,1\n1,0,\n0,1,1\n1,1,1\n", "young_modulus", " line 3: no value for E (the line has 2 of the 3 "
     "columns x, y, E); give a number in every column or remove the line"),
    ("x,y,E\n0,0,1\n1,,1\n0,1,1\n1,1,1\n", "young_modulus", " line 3: no value for y; give a number in every column "
     "or remove the line"),
    ("x,y,E\n0,0,1\n1,0,soft\n0,1,1\n1,1,1\n", "young_modulus", " line 3: E is 'soft', not a number; give a number "
     "in every column or remove the line"),
    ("x,y,E\n0,0,1,7\n1,0,1\n0,1,1\n1,1,1\n", "young_modulus", " line 2: 4 values, but the header names 3 columns "
     "(x, y, E); give one value per column"),
    # a point given twice, with the same or another value, in 1, 2 and 3 dimensions (a grid, or not)
    ("z,E\n0,1\n0,2\n-1,1\n", "young_modulus", ": the point z = 0 is given twice (lines 2 and 3) with different "
     "values of E (1 and 2); give each point once (remove the extra lines)"),
    ("x,y,E\n0,0,1\n1,0,2\n0,1,3\n1,1,4\n1,1,5\n", "young_modulus", ": the point x = 1, y = 1 is given twice (lines "
     "5 and 6) with different values of E (4 and 5); give each point once (remove the extra lines)"),
    ("x,y,E\n0,0,1\n1,0,2\n0,1,3\n1,1,4\n1,1,4\n0,0,1\n", "young_modulus", ": the point x = 0, y = 0 is given twice "
     "(lines 2 and 7) with the same value; 1 more point is given more than once; give each point once (remove the "
     "extra lines)"),
    ("x,y,z,E\n" + "".join(f"{i},{j},{k},1\n" for i in (0, 1) for j in (0, 1) for k in (0, 1)) + "1,0,1,1\n1,0,1,2\n",
     "young_modulus", ": the point x = 1, y = 0, z = 1 is given 3 times (lines 7, 10 and 11) with different values "
     "of E (1, 1 and 2); give each point once (remove the extra lines)"),
    # too few points
    ("x,y,E\n5,5,1e6\n", "young_modulus", ": one point (line 2); a field in x, y needs at least 3 points not on one "
     "line: give more points, or the property as a number instead of field:"),
    ("x,y,E\n0,0,1\n1,0,2\n2,0,3\n", "young_modulus", ": the grid has one y value; give at least two, or leave y out "
     "of the file for a field that does not vary with y"),
]


@pytest.mark.parametrize("text, prop, message", BAD_CSV)
def test_bad_files(tmp_path, text, prop, message):
    path = tmp_path / "f.csv"
    path.write_text(text)
    option = f"pfault_material_clay_{prop}"
    with pytest.raises(InputError) as err:
        pr.read_fields([pr.FieldRef(option, str(path), unit="Pa" if prop == "young_modulus" else "")], "")
    assert str(err.value) == f"-{option} field:{path}{message}"


def test_bad_hdf5_and_other_files(tmp_path):
    """The HDF5 counterparts (a coordinate that repeats a value or goes back and forth, only coordinates, a point
    twice among scattered points), a directory, a GeoTIFF and a binary file."""
    def h5(name, **data):
        with h5py.File(tmp_path / name, "w") as f:
            for k, v in data.items():
                f[k] = v
        return str(tmp_path / name)

    def message(path):
        with pytest.raises(InputError) as err:
            read_field(path, OPTION, "Pa")
        assert str(err.value).startswith(f"-{OPTION} field:{path}: "), err.value
        return str(err.value)[len(f"-{OPTION} field:{path}: "):]

    e = np.ones((2, 3))
    assert message(h5("rep.h5", x=[0.0, 100.0, 100.0], y=[0.0, 1.0], E=e)) == (
        "the coordinate variable x gives x = 100 twice (indices 1 and 2); a grid gives each x once")
    assert message(h5("order.h5", x=[0.0, 300.0, 100.0], y=[0.0, 1.0], E=e)) == (
        "the coordinate variable x is not in order (x[1] = 300, x[2] = 100); sort it, increasing or decreasing, "
        "with the values along it")
    assert message(h5("coords.h5", x=[0.0, 1.0], y=[0.0, 1.0])) == (
        "the file has only coordinate variables (x, y) and no value; add the value's variable (e.g. a variable "
        "value with a units attribute)")
    assert message(h5("pts.h5", x=[0.0, 1.0, 0.0, 1.0], y=[0.0, 0.0, 1.0, 0.0], E=[1.0, 2.0, 3.0, 4.0])) == (
        "the point x = 1, y = 0 is given twice (entries 1 and 3) with different values of E (2 and 4); give each "
        "point once (remove the extra entries)")
    assert message(str(tmp_path)) == "is a directory, not a file; give the path of a CSV, HDF5 or NetCDF file"
    (tmp_path / "map.tif").write_bytes(b"II*\x00" + bytes(100))
    assert message(str(tmp_path / "map.tif")) == (
        "a (Geo)TIFF, which pfault does not read; convert it to NetCDF (gdal_translate -of netCDF in.tif out.nc) "
        "and give that file, with its units attribute")
    (tmp_path / "map.bin").write_bytes(bytes(range(128, 256)))
    assert message(str(tmp_path / "map.bin")) == (
        "neither a text (CSV) file nor HDF5 or NetCDF; give a CSV file with a header line, or an HDF5 or NetCDF file")


def test_north_up_grid_is_turned_round(tmp_path):
    """A grid stored with y decreasing (north-up, as rasters are) gives the values of the same grid stored
    increasing; a spreadsheet's byte-order mark and empty fields at the ends of lines are ignored."""
    e = np.array([[MAP_E[i, j] for i in range(3)] for j in range(2)])        # (ny, nx) MPa
    with h5py.File(tmp_path / "up.h5", "w") as h5:
        h5["x"], h5["y"], h5["young_modulus"] = MAP_X, MAP_Y[::-1], e[::-1] * 1e6
    with h5py.File(tmp_path / "up_x.h5", "w") as h5:
        h5["x"], h5["y"], h5["young_modulus"] = MAP_X[::-1], MAP_Y, e[:, ::-1] * 1e6
    pts = np.array([[50.0, 50.0, 0.0], [250.0, 150.0, 0.0], [100.0, 200.0, 0.0]])
    expect = [7.25e6, 15.125e6, 12e6]                       # test_map_is_bilinear_by_hand
    for name in ("up.h5", "up_x.h5"):
        assert pr.interpolate(read_field(str(tmp_path / name), OPTION, "Pa"), pts)[0] == pytest.approx(expect,
                                                                                                      rel=1e-14)
    text = write_map_csv(tmp_path / "map.csv")
    lines = open(text).read().splitlines()
    (tmp_path / "excel.csv").write_text("\ufeff" + "".join(f"{ln},,\n" for ln in lines), encoding="utf-8")
    field = read_field(str(tmp_path / "excel.csv"), OPTION, "Pa")
    assert field.is_grid and pr.interpolate(field, pts)[0] == pytest.approx(expect, rel=1e-14)


def test_points_that_look_like_a_grid_are_noted(tmp_path):
    """Points filling most of the grid of their distinct coordinates, but not all of it (a node left out,
    a coordinate off by round-off), are scattered points with a note saying why; a full grid and points
    scattered at random have none."""
    path = tmp_path / "f.csv"
    nodes = [(x, y) for x in (0.0, 100.0, 200.0, 300.0) for y in (0.0, 100.0, 200.0)]

    def read(pts):
        path.write_text("x,y,E\n" + "".join(f"{x!r},{y!r},{1e6 + x + y}\n" for x, y in pts))
        return read_field(str(path), OPTION, "Pa")

    where = f"-{OPTION} field:{path}: "
    tail = ("; they are read as scattered points (linear between neighbouring points), not as a grid; give every "
            "node of the grid once for (multi)linear interpolation on it")
    field = read(nodes[:-1])
    assert not field.is_grid and field.note == (where + "the 11 points lie on the 4 x 3 grid of their distinct x, y "
                                                "values but leave 1 of its nodes empty (e.g. x = 300, y = 200)" + tail)
    jitter = [(x + (1e-5 if (x, y) == (100.0, 100.0) else 0.0), y) for x, y in nodes]
    field = read(jitter)
    assert not field.is_grid and field.note == (
        where + "the 12 points lie on the 5 x 3 grid of their distinct x, y values but leave 3 of its nodes empty "
        "(e.g. x = 100, y = 100), and x = 100 and 100.00001 differ by only 1e-05 m (round-off?)" + tail)
    assert read(nodes).is_grid and read(nodes).note == ""
    rng = np.random.default_rng(0)
    field = read(rng.uniform(0, 1000, (30, 2)))
    assert not field.is_grid and field.note == ""
    notes = []
    mesh = box_mesh((300.0, 200.0, 30.0), (3, 2, 1), materials=("clay",))
    read(nodes[:-1])
    mats = [Material("clay", ref(path, outside="nearest"), 0.3, 1.0, 2000.0)]
    pr.serial_field_values(["clay"], pr.field_refs(mats), mesh.points, mesh.tets, mesh.cell_material, "", notes=notes)
    assert notes == [read_field(str(path), OPTION, "Pa").note] and notes[0].startswith(where + "the 11 points")


def test_wrong_variable_name_and_syntax(tmp_path):
    path = write_map_csv(tmp_path / "map.csv")
    with pytest.raises(InputError, match="no variable 'E' .the file has young_modulus.; give one of them"):
        pr.read_fields([ref(path, variable="E")], "")
    with pytest.raises(InputError, match="outside=zero in .*; give outside=error or outside=nearest"):
        pr.parse_field(f"field:{path},outside=zero", OPTION, "Pa")
    assert pr.parse_field(f"field:{path}, variable=young_modulus ,outside=nearest", OPTION, "Pa") == \
        pr.FieldRef(OPTION, path, "young_modulus", "nearest", "Pa")


def test_path_beside_the_scene(tmp_path, monkeypatch):
    write_map_csv(tmp_path / "map.csv")
    monkeypatch.chdir("/")
    assert beside_scene("map.csv", str(tmp_path / "scene.opts")) == str(tmp_path / "map.csv")
    assert beside_scene("nowhere.csv", str(tmp_path / "scene.opts")) == "nowhere.csv"
