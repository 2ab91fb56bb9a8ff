"""A groundwater model's heads as a pore-pressure source (pfault.sources.heads), in-process on one rank:

- MODFLOW 6 grid (DIS, DISV) and head files written from NumPy (pfault.tools.mf6_write) read back unchanged by flopy;
- the cell of a point (DIS with rotation, DISV of triangles and quadrilaterals, the layer from TOP/BOTM) equals
  flopy's own grid intersection;
- a head field varying in x gives each cell the head of the MODFLOW cell of its centroid, linear in time between
  saved times, dp = rho_w g (h - h_ref); dry and inactive cells as documented;
- the generic HDF5 layout reproduces a linear field exactly (grid: multilinear; points: Delaunay);
- bad files: one line naming the file and the fix; files cut short; heads that change no cell; a reference after
  the run's time 0 (a warning);
- the cells a source leaves unloaded (pfault.sources.coverage).
"""

import dataclasses

import flopy
import h5py
import numpy as np
import pytest
from flopy.mf6.utils import MfGrdFile
from mpi4py import MPI

from pfault.errors import InputError
from pfault.physics.loading import MaterialDrawdown, Table
from pfault.sources import TableSource, lookup, zero_on
from pfault.sources.coverage import measure
from pfault.sources.head_files import read_mf6_grid
from pfault.sources.heads import HeadsSettings, HeadsSource, build_heads_source, check_heads_files
from pfault.tools.mf6_write import write_dis_grb, write_disv_grb, write_heads

RHO_G = 1000.0 * 9.80665


def settings(path, grid="", **kw):
    base = dict(file=str(path), grid=str(grid) if grid else "", time_unit=86400.0, time_unit_given=False,
                length_unit=1.0, reference_time=None, outside="error", origin=(0.0, 0.0, 0.0), water_density=1000.0,
                gravity=9.80665)
    base.update(kw)
    return HeadsSettings(**base)


def dis_model(tmp_path, angrot=0.0, xorigin=0.0, yorigin=0.0, idomain=None):
    rng = np.random.default_rng(3)
    delr, delc = rng.uniform(5, 15, 7), rng.uniform(5, 15, 5)
    top = rng.uniform(9, 11, (5, 7))
    botm = np.stack([top - rng.uniform(8, 12, (5, 7)), np.full((5, 7), -40.0), np.full((5, 7), -60.0)])
    path = tmp_path / "m.dis.grb"
    write_dis_grb(str(path), delr, delc, top, botm, idomain=idomain, xorigin=xorigin, yorigin=yorigin,
                  angrot=angrot)
    return path, delr, delc, top, botm


def vertex_model(tmp_path, angrot=0.0, xorigin=0.0, yorigin=0.0):
    """Triangles and quadrilaterals on a sheared 6 x 4 lattice, two layers."""
    nx, ny = 6, 4
    verts = np.array([[i * 10.0 + 3.0 * (j % 2), j * 7.5] for j in range(ny + 1) for i in range(nx + 1)])
    cells = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 1, a + nx + 2
            cells += [[a, c, d, b]] if (i + j) % 2 else [[a, c, d], [a, d, b]]
    n = len(cells)
    top, botm = np.full(n, 5.0), np.stack([np.full(n, -5.0), np.full(n, -25.0)])
    path = tmp_path / "m.disv.grb"
    write_disv_grb(str(path), verts, cells, top, botm, xorigin=xorigin, yorigin=yorigin, angrot=angrot)
    return path, verts, cells, top, botm


def test_dis_files_read_back_unchanged_by_flopy(tmp_path):
    idomain = np.ones((3, 5, 7), int)
    idomain[2, 0, :3] = 0
    path, delr, delc, top, botm = dis_model(tmp_path, angrot=25.0, xorigin=1e5, yorigin=2e5, idomain=idomain)
    g = MfGrdFile(str(path))
    assert g.grid_type == "DIS" and (g.nlay, g.nrow, g.ncol) == (3, 5, 7) and g.ncells == 105
    assert (g.xorigin, g.yorigin, g.angrot) == (1e5, 2e5, 25.0)
    assert np.array_equal(g.delr, delr) and np.array_equal(g.delc, delc)
    assert np.array_equal(g.top.reshape(5, 7), top) and np.array_equal(g.bot.reshape(3, 5, 7), botm)
    assert np.array_equal(g.idomain.reshape(3, 5, 7), idomain)
    # connectivity: each cell first, then its 2-6 face neighbours (MODFLOW's IA/JA)
    assert g.nja == 105 + 2 * (2 * 35 + 3 * 6 * 5 + 3 * 4 * 7)
    assert np.array_equal(g.ja[g.ia[:-1]], np.arange(105))
    times = [1.0, 30.0, 365.0]
    heads = np.random.default_rng(0).normal(size=(3, 3, 5, 7))
    heads[2, 0, 1, 1] = -1e30
    write_heads(str(tmp_path / "m.hds"), times, heads)
    hf = flopy.utils.HeadFile(str(tmp_path / "m.hds"))
    assert hf.get_times() == times and (hf.nlay, hf.nrow, hf.ncol) == (3, 5, 7)
    for t, h in zip(times, heads):
        assert np.array_equal(hf.get_data(totim=t), h)
    rec = hf.recordarray
    assert list(rec["kper"]) == [1, 1, 1, 2, 2, 2, 3, 3, 3] and list(rec["ilay"]) == [1, 2, 3] * 3
    assert {r.strip() for r in rec["text"]} == {b"HEAD"}
    hf.close()


def test_disv_files_read_back_unchanged_by_flopy(tmp_path):
    path, verts, cells, top, botm = vertex_model(tmp_path, angrot=-10.0, xorigin=50.0, yorigin=-20.0)
    g = MfGrdFile(str(path))
    assert g.grid_type == "DISV" and (g.nlay, g.ncpl) == (2, len(cells))
    assert (g.xorigin, g.yorigin, g.angrot) == (50.0, -20.0, -10.0)
    assert np.array_equal(g.verts, verts)
    assert [list(c[:-1]) for c in g.iverts] == [list(c) for c in cells]
    assert np.array_equal(g.top, top) and np.array_equal(g.bot.reshape(2, -1), botm)
    centres = np.array([verts[c].mean(axis=0) for c in cells])
    assert np.allclose(g.cellcenters, centres)
    heads = np.random.default_rng(1).normal(size=(2, 2, len(cells)))
    write_heads(str(tmp_path / "m.hds"), [0.0, 10.0], heads)
    hf = flopy.utils.HeadFile(str(tmp_path / "m.hds"))
    assert hf.get_times() == [0.0, 10.0]
    assert np.array_equal(hf.get_data(totim=10.0)[:, 0, :], heads[1])
    hf.close()


def flopy_cells(mg, x, y, z, ncpl):
    """flopy's StructuredGrid/VertexGrid.intersect, point by point, as flat cell numbers (-1 outside)."""
    out = []
    for xi, yi, zi in zip(x, y, z):
        r = mg.intersect(xi, yi, zi, forgive=True)
        if np.any(np.isnan(np.asarray(r, float))):
            out.append(-1)
        elif len(r) == 3:       # (layer, row, column)
            out.append(int(r[0]) * ncpl + int(r[1]) * mg.ncol + int(r[2]))
        else:                   # (layer, cell2d)
            out.append(int(r[0]) * ncpl + int(r[1]))
    return np.array(out)


@pytest.mark.parametrize("kind", ["DIS", "DISV"])
def test_cell_of_a_point_is_flopys(tmp_path, kind):
    if kind == "DIS":
        path, *_ = dis_model(tmp_path, angrot=30.0, xorigin=500.0, yorigin=-300.0)
        box = (470, 565, -305, -218)
    else:
        path, *_ = vertex_model(tmp_path, angrot=-20.0, xorigin=-3.0, yorigin=4.0)
        box = (-10, 80, -30, 30)
    rng = np.random.default_rng(7)
    n = 3000
    pts = np.stack([rng.uniform(*box[:2], n), rng.uniform(*box[2:], n), rng.uniform(-70, 15, n)], axis=1)
    grid = read_mf6_grid(str(path))
    mine = grid.cells(pts)
    theirs = flopy_cells(MfGrdFile(str(path)).modelgrid, *pts.T, grid.ncpl)
    assert np.array_equal(mine, theirs)
    assert 100 < np.sum(mine >= 0) < 0.9 * n             # points inside and outside, in every layer
    assert len(np.unique(mine[mine >= 0] // grid.ncpl)) == grid.nlay


def test_points_on_edges_go_to_the_lower_cell_number():
    delr, delc = np.array([1.0, 2.0]), np.array([1.0, 1.0])
    x = np.array([0.0, 1.0, 3.0, 1.0, 3.1])
    y = np.array([2.0, 1.0, 0.0, 1.5, 1.0])
    assert list(lookup.structured_cell(delr, delc, x, y)) == [0, 0, 3, 0, -1]


def x_varying(tmp_path, times=(0.0, 10.0, 30.0)):
    """A 1-layer DIS model, 10 columns of 10 m, head h = 20 - 0.1 x_c - 0.5 t (t in days) at column centre x_c."""
    write_dis_grb(str(tmp_path / "x.dis.grb"), np.full(10, 10.0), [50.0], np.full((1, 10), 0.0),
                  np.full((1, 1, 10), -100.0))
    xc = np.arange(10) * 10.0 + 5.0
    heads = np.array([(20 - 0.1 * xc - 0.5 * t)[None, None, :] for t in times])
    write_heads(str(tmp_path / "x.hds"), times, heads)
    return settings(tmp_path / "x.hds", tmp_path / "x.dis.grb")


def test_a_head_field_varying_in_x_is_looked_up_and_interpolated_in_time(tmp_path):
    s = x_varying(tmp_path)
    rng = np.random.default_rng(5)
    centroids = np.stack([rng.uniform(0, 100, 200), rng.uniform(0, 50, 200), rng.uniform(-100, 0, 200)], axis=1)
    src = build_heads_source(MPI.COMM_SELF, s, centroids)
    xc = np.floor(centroids[:, 0] / 10.0) * 10.0 + 5.0
    day = 86400.0
    for t_day in (0.0, 4.0, 10.0, 17.5, 30.0):
        # the reference is the first saved head: dp = rho_w g (h(t) - h(0)), h linear in t between saved times
        expected = RHO_G * (-0.5 * t_day) * np.ones_like(xc)
        assert np.allclose(src.cell_dp(t_day * day), expected, rtol=1e-13, atol=1e-9)
    s2 = HeadsSettings(**{**s.__dict__, "reference_time": 10.0 * day})
    src2 = build_heads_source(MPI.COMM_SELF, s2, centroids)
    assert np.allclose(src2.cell_dp(0.0), RHO_G * 5.0, rtol=1e-13)
    # the head itself varies in x: against a reference field of zero head the cells see h(x_c)
    heads = flopy.utils.HeadFile(str(tmp_path / "x.hds"))
    h0 = heads.get_data(totim=0.0).ravel()
    heads.close()
    assert np.allclose(h0[np.floor(centroids[:, 0] / 10.0).astype(int)], 20 - 0.1 * xc)
    assert src.cell_dp(5 * day) is not src.cell_dp(5 * day)         # a new array: cell_dp changes nothing


def test_reference_time_must_be_saved_and_the_run_within_the_file(tmp_path):
    s = x_varying(tmp_path)
    with pytest.raises(InputError, match=r"-pfault_heads_reference_time 865000 s is not a time saved in .*x\.hds "
                                         r"\(saved, in units of 86400 s: 0, 10, 30\); give one of them"):
        check_heads_files(HeadsSettings(**{**s.__dict__, "reference_time": 10 * 86400.0 + 1e3}), 1.0)
    with pytest.raises(InputError, match=r"-pfault_time_end 3e\+06 s is after the last time saved in .*x\.hds "
                                         r"\(2\.592e\+06 s\); end the run by then or give heads up to its end"):
        check_heads_files(s, 3e6)
    check_heads_files(s, 30 * 86400.0)


def test_dry_and_inactive_cells(tmp_path):
    """Two layers (0..-10, -10..-20) of 4 columns; the top layer's column 1 goes dry, column 2 is dry at the
    reference and wet again later, column 3 is inactive (IDOMAIN 0)."""
    idomain = np.ones((2, 1, 4), int)
    idomain[0, 0, 3] = 0
    write_dis_grb(str(tmp_path / "d.dis.grb"), np.full(4, 10.0), [10.0], np.zeros((1, 4)),
                  np.stack([np.full((1, 4), -10.0), np.full((1, 4), -20.0)]), idomain=idomain)
    h0 = np.array([[[-2.0, -3.0, -1e30, 1e30]], [[-2.0, -3.0, -4.0, -5.0]]])
    h1 = np.array([[[-4.0, -1e30, -6.0, 1e30]], [[-4.0, -12.0, -6.0, -5.0]]])
    write_heads(str(tmp_path / "d.hds"), [0.0, 1.0], np.stack([h0, h1]))
    s = settings(tmp_path / "d.hds", tmp_path / "d.dis.grb", outside="zero")
    centroids = np.array([[5.0, 5.0, -5.0], [15.0, 5.0, -5.0], [25.0, 5.0, -5.0], [35.0, 5.0, -5.0],
                          [15.0, 5.0, -15.0], [25.0, 5.0, -8.0]])
    dp = build_heads_source(MPI.COMM_SELF, s, centroids).cell_dp(86400.0)
    expected = RHO_G * np.array([
        -2.0,                   # wet at both times: rho_w g (h - h_ref)
        -(-3.0 - (-5.0)),       # dry now: pore pressure 0, dp = -rho_w g (h_ref - z) = -2 m of water
        0.0,                    # dry at the reference, wet at -6 < z = -5: no pore pressure either time
        0.0,                    # inactive, -pfault_heads_outside zero
        -9.0,                   # lower layer, wet
        2.0])                   # dry at the reference, wet now at h = -6 above z = -8: 2 m of water
    assert np.allclose(dp, expected, rtol=1e-13)
    with pytest.raises(InputError, match=r"1 of 6 mesh cells have their centroid outside the groundwater model "
                                         r"or in its inactive cells \(site coordinates x 35\.\.35, y 5\.\.5, "
                                         r"z -5\.\.-5 m; the model spans x 0\.\.40, y 0\.\.10, z -20\.\.0 m\); "
                                         r"check what places the mesh in the model: -pfault_mesh_origin \(site = "
                                         r"mesh \+ origin\), -pfault_heads_length_unit \(the model's length unit in "
                                         r"metres, 0\.3048 for feet; now 1\) and -pfault_heads_grid .*d\.dis\.grb "
                                         r"\(the grid file of the model that wrote the heads, whose XORIGIN, YORIGIN "
                                         r"and ANGROT place it\), or say what they get: -pfault_heads_outside zero"):
        build_heads_source(MPI.COMM_SELF, settings(tmp_path / "d.hds", tmp_path / "d.dis.grb"), centroids)


def test_mesh_origin_and_length_unit(tmp_path):
    """A model in feet whose grid starts at (1000 ft, 2000 ft): a mesh at origin (304.8, 609.6, 0) m sees its
    first column; heads in feet give dp = rho_w g 0.3048 dh."""
    write_dis_grb(str(tmp_path / "f.dis.grb"), [10.0, 10.0], [10.0], np.zeros((1, 2)), np.full((1, 1, 2), -50.0),
                  xorigin=1000.0, yorigin=2000.0)
    write_heads(str(tmp_path / "f.hds"), [0.0, 1.0], np.array([[[[0.0, 0.0]]], [[[-10.0, -20.0]]]]))
    s = settings(tmp_path / "f.hds", tmp_path / "f.dis.grb", length_unit=0.3048, origin=(304.8, 609.6, 0.0))
    dp = build_heads_source(MPI.COMM_SELF, s, np.array([[1.0, 1.0, -1.0], [4.0, 1.0, -1.0]])).cell_dp(86400.0)
    assert np.allclose(dp, RHO_G * 0.3048 * np.array([-10.0, -20.0]), rtol=1e-13)


def write_h5(path, times, values, units="day", **axes):
    with h5py.File(path, "w") as f:
        f["time"] = np.asarray(times, float)
        if units:
            f["time"].attrs["units"] = units
        for k, v in axes.items():
            f[k] = np.asarray(v, float)
        f["head" if "pressure" not in str(path) else "pressure_change"] = values


def test_generic_grid_and_points_reproduce_a_linear_field(tmp_path):
    rng = np.random.default_rng(11)
    x, y, z = np.linspace(0, 100, 6), np.linspace(-50, 50, 5), np.linspace(-80, 0, 4)

    def field(px, py, pz, t):
        return 3.0 + 0.02 * px - 0.05 * py + 0.1 * pz - 2.0 * t

    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    values = np.stack([field(X, Y, Z, t) for t in (0.0, 2.0)])
    write_h5(tmp_path / "g.h5", [0.0, 2.0], values, units="days since 2001-01-01", x=x, y=y, z=z)
    pts = np.stack([rng.uniform(0, 100, 300), rng.uniform(-50, 50, 300), rng.uniform(-80, 0, 300)], axis=1)
    src = build_heads_source(MPI.COMM_SELF, settings(tmp_path / "g.h5"), pts)
    assert np.allclose(src.cell_dp(86400.0), RHO_G * -2.0, rtol=1e-12)
    nodes = np.array([[0, 0], [100, 0], [100, 100], [0, 100], [40, 60], [70, 20]], float)
    pv = np.stack([field(nodes[:, 0], nodes[:, 1], 0.0, t) for t in (0.0, 1.0)])
    write_h5(tmp_path / "p_pressure.h5", [0.0, 1.0], 1e3 * pv, units="", points=nodes)
    q = np.stack([rng.uniform(0, 100, 300), rng.uniform(0, 100, 300), rng.uniform(-80, 0, 300)], axis=1)
    src = build_heads_source(MPI.COMM_SELF, settings(tmp_path / "p_pressure.h5"), q)
    # pressure changes are used as they are (no reference subtracted), linear in the plane, at every depth
    assert np.allclose(src.cell_dp(0.0), 1e3 * field(q[:, 0], q[:, 1], 0.0, 0.0), rtol=1e-12)
    assert np.allclose(src.cell_dp(0.5 * 86400.0), 1e3 * field(q[:, 0], q[:, 1], 0.0, 0.5), rtol=1e-12)
    with pytest.raises(InputError, match="outside the extent of the file's grid or points"):
        build_heads_source(MPI.COMM_SELF, settings(tmp_path / "g.h5"), pts + [0.0, 0.0, 10.0])


def test_bad_files_are_one_line_naming_the_file_and_the_fix(tmp_path):
    s = x_varying(tmp_path)
    write_dis_grb(str(tmp_path / "other.dis.grb"), np.full(9, 10.0), [50.0], np.zeros((1, 9)),
                  np.full((1, 1, 9), -100.0))
    cases = [
        (settings(s.file, tmp_path / "other.dis.grb"), r"its records are 1 x 10 \(rows x columns\) in up to 1 "
         r"layers, but the grid file .*other\.dis\.grb has 1 layers of 1 x 9; give the grid file of the model that "
         r"wrote these heads"),
        (settings(tmp_path / "missing.hds", s.grid), r"-pfault_heads_file .*missing\.hds: no such file"),
        (settings(s.grid, s.grid), r"not a MODFLOW head file"),
        (settings(s.file, s.file), r"-pfault_heads_grid .*x\.hds: not a MODFLOW 6 binary grid file"),
    ]
    write_heads(str(tmp_path / "back.hds"), [0.0, 10.0, 5.0], np.zeros((3, 1, 1, 10)))
    cases.append((settings(tmp_path / "back.hds", s.grid), r"its saved times are not increasing \(time 5 after "
                  r"10\); give the head file of one run, its records in time order"))
    nan = np.zeros((2, 1, 1, 10))
    nan[1, 0, 0, 3] = np.nan
    write_heads(str(tmp_path / "nan.hds"), [0.0, 10.0], nan)
    write_h5(tmp_path / "nan.h5", [0.0, 1.0], np.array([[[0.0, 1.0]], [[np.nan, 1.0]]]), x=[0.0, 1.0], y=[0.0])
    write_h5(tmp_path / "shape.h5", [0.0, 1.0], np.zeros((2, 3)), x=[0.0, 1.0], y=[0.0])
    for case in cases:
        with pytest.raises(InputError, match=case[1]) as err:
            check_heads_files(case[0], 1.0)
        assert "\n" not in str(err.value)
    with pytest.raises(InputError, match=r"1 heads are NaN at time 10; MODFLOW writes dry cells as -1e30"):
        build_heads_source(MPI.COMM_SELF, settings(tmp_path / "nan.hds", s.grid), np.array([[1.0, 1.0, -1.0]]))
    with pytest.raises(InputError, match=r"nan\.h5: 'head' holds 1 NaN or infinite values at time 1"):
        build_heads_source(MPI.COMM_SELF, settings(tmp_path / "nan.h5"), np.array([[0.5, 0.0, 0.0]]))
    with pytest.raises(InputError, match=r"shape\.h5: 'head' is \(2, 3\), the times and axes ask for \(2, 1, 2\)"):
        check_heads_files(settings(tmp_path / "shape.h5"), 1.0)


def two_columns(tmp_path, times, heads, bottom=-100.0):
    """A one-layer DIS model of two 5 m columns over (0..10) x (0..10), its top at 0 m: (settings, centroids of
    four cells, two per column, one at z -25 and one at -75)."""
    write_dis_grb(str(tmp_path / "c.dis.grb"), [5.0, 5.0], [10.0], np.zeros((1, 2)), np.full((1, 1, 2), bottom))
    write_heads(str(tmp_path / "c.hds"), times, np.asarray(heads, float).reshape(len(times), 1, 1, 2))
    centroids = np.array([[2.5, 5.0, -25.0], [7.5, 5.0, -25.0], [2.5, 5.0, -75.0], [7.5, 5.0, -75.0]])
    return settings(tmp_path / "c.hds", tmp_path / "c.dis.grb"), centroids


def test_heads_that_change_no_cell_are_one_line_naming_the_reason(tmp_path):
    """Heads that load no cell up to the run's end stop the run: a file of one saved time (its heads are the
    reference), heads equal to the reference at every saved time up to the end (though they change after it), every
    cell outside the model under -pfault_heads_outside zero (the line names every option that places the mesh)."""
    s, c = two_columns(tmp_path, [3.0], [[1.0, 2.0]])
    with pytest.raises(InputError) as err:
        build_heads_source(MPI.COMM_SELF, s, c, 3 * 86400.0)
    assert str(err.value) == (
        f"-pfault_heads_file {s.file}: it holds the heads of one saved time (3 days), which are the reference heads "
        "h_ref, so dp = rho_w g (h - h_ref) is zero at every time; give a file with the heads of the times after "
        "the reference too (MODFLOW: SAVE HEAD at every stress period)")
    s, c = two_columns(tmp_path, [0.0, 5.0, 10.0], [[1.0, 2.0], [1.0, 2.0], [0.0, 2.0]])
    with pytest.raises(InputError) as err:
        build_heads_source(MPI.COMM_SELF, s, c, 5 * 86400.0)
    assert str(err.value) == (
        f"-pfault_heads_file {s.file}: the heads at every saved time up to the run's end (5 days) equal the "
        "reference heads, those of 0 s, so there is no pore-pressure change; give the head file of the run whose "
        "heads change, or choose the reference with -pfault_heads_reference_time (a saved time)")
    # a day later the first column's heads have begun to change: the run goes on
    src = build_heads_source(MPI.COMM_SELF, s, c, 6 * 86400.0)
    assert src.unchanged(6 * 86400.0).tolist() == [False, True, False, True]
    assert src.unchanged(5 * 86400.0).all() and src.notes["warnings"] == []
    far = dataclasses.replace(s, origin=(1000.0, 0.0, 0.0), outside="zero")
    with pytest.raises(InputError) as err:
        build_heads_source(MPI.COMM_SELF, far, c, 6 * 86400.0)
    assert str(err.value) == (
        f"-pfault_heads_file {s.file}: all 4 mesh cells have their centroid outside the groundwater model or in its "
        "inactive cells, so -pfault_heads_outside zero gives none of them a pore-pressure change and the run has no "
        "load; check what places the mesh in the model: -pfault_mesh_origin (site = mesh + origin), "
        "-pfault_heads_length_unit (the model's length unit in metres, 0.3048 for feet; now 1) and "
        f"-pfault_heads_grid {s.grid} (the grid file of the model that wrote the heads, whose XORIGIN, YORIGIN and "
        "ANGROT place it)")


def test_a_reference_after_time_zero_is_a_warning_unless_chosen(tmp_path, capsys):
    """Heads whose first saved time is 1 year into the run become the reference with a warning (printed once,
    recorded in the notes summary.json takes); choosing that reference says it is meant, and nothing is printed."""
    s, c = two_columns(tmp_path, [365.25, 730.5], [[1.0, 2.0], [0.0, 0.0]])
    src = build_heads_source(MPI.COMM_SELF, s, c, 730.5 * 86400.0)
    err = capsys.readouterr().err
    line = (f"pfault: warning: -pfault_heads_file {s.file}: the reference heads h_ref are those of its first saved "
            "time, 365.25 days, not of the run's time 0: drawdown before that time (pumping that started earlier) "
            "is not in the load; if the model was at rest then, say so with -pfault_heads_reference_time "
            "365.25*day (this warning then goes), else give heads from before pumping (a steady-state first stress "
            "period)")
    assert err == line + "\n"
    assert src.notes == {"reference_time_s": 365.25 * 86400.0, "reference_chosen": False, "saved_times": 2,
                         "warnings": [line.removeprefix("pfault: warning: ")]}
    chosen = dataclasses.replace(s, reference_time=365.25 * 86400.0)
    src = build_heads_source(MPI.COMM_SELF, chosen, c, 730.5 * 86400.0)
    assert capsys.readouterr().err == "" and src.notes["reference_chosen"] and src.notes["warnings"] == []


def test_cut_head_and_grid_files_are_one_line(tmp_path):
    """A head file cut inside its last record's values or inside a record's header, a grid file cut inside its
    values or inside its text header, an HDF5 file cut short: each is one line saying so (no EOFError from flopy,
    no reshape error, no run on a grid whose last arrays are missing); a grid file given as the head file is still
    'not a MODFLOW head file'."""
    s, _ = two_columns(tmp_path, [0.0, 1.0, 2.0], np.zeros((3, 2)))
    whole = (tmp_path / "c.hds").read_bytes()
    grid = (tmp_path / "c.dis.grb").read_bytes()
    fix = ("the copy or the model run that wrote it stopped before the end: copy the file again, or run the model to "
           "its end")
    cases = [("c.hds", whole[:-3], "heads", f"cut short: the file is {len(whole) - 3:,} bytes, but its last record "
              f"(time 2, layer 1) ends at byte {len(whole):,}; {fix}"),
             ("c.hds", whole[:-(16 + 20)], "heads", f"cut short: the file ends inside the header of a record; {fix}"),
             ("c.dis.grb", grid[:-5], "grid", f"cut short: the file is {len(grid) - 5:,} bytes, its header describes "
              f"{len(grid):,}; {fix}"),
             ("c.dis.grb", grid[:230], "grid", f"cut short: the file ends inside its text header; {fix}")]
    for name, data, which, message in cases:
        (tmp_path / "cut").mkdir(exist_ok=True)
        path = tmp_path / "cut" / name
        path.write_bytes(data)
        cut = dataclasses.replace(s, **{"file" if which == "heads" else "grid": str(path)})
        with pytest.raises(InputError) as err:
            check_heads_files(cut, 1.0)
        option = "-pfault_heads_file" if which == "heads" else "-pfault_heads_grid"
        assert str(err.value) == f"{option} {path}: {message}"
        path.unlink()
    with pytest.raises(InputError, match="not a MODFLOW head file"):
        check_heads_files(dataclasses.replace(s, file=s.grid), 1.0)
    write_h5(tmp_path / "g.h5", [0.0, 1.0], np.zeros((2, 1, 2)), x=[0.0, 1.0], y=[0.0])
    data = (tmp_path / "g.h5").read_bytes()
    (tmp_path / "g.h5").write_bytes(data[:-100])
    with pytest.raises(InputError, match=r"g\.h5: cut short \(HDF5: .*truncated file.*\); the copy or the model run"):
        check_heads_files(settings(tmp_path / "g.h5"), 1.0)


def test_coverage_counts_cells_and_volume_without_a_change():
    """pfault.sources.coverage on one rank: the cells a source leaves unloaded over [0, t_end] and their share of
    the volume; tables: a material without a table, or with one that is zero up to t_end, loads none of its cells."""
    assert zero_on([0.0, 10.0, 20.0], [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0]], 10.0).tolist() == [True, False]
    assert zero_on([0.0, 10.0, 20.0], [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0]], 11.0).tolist() == [False, False]
    assert zero_on([5.0], [[0.0, 2.0]], 9.0).tolist() == [True, False]
    tables = MaterialDrawdown([Table((0.0, 10.0), (0.0, -1.0)), None, Table((0.0, 5.0, 10.0), (0.0, 0.0, -1.0))])
    source = TableSource(tables, np.array([0, 1, 2, 2]))
    volumes = np.array([1.0, 2.0, 3.0, 4.0])
    cov = measure(MPI.COMM_SELF, source, volumes, 5.0)
    assert (cov.source, cov.cells, cov.unloaded_cells, cov.outside_cells) == ("tables", 4, 3, None)
    assert cov.unloaded_volume_fraction == pytest.approx(0.9, rel=1e-15)
    assert cov.line() == "pfault: pore-pressure change in 1 of 4 cells (10 % of the volume); none in 3 (90 %)"
    assert measure(MPI.COMM_SELF, source, volumes, 10.0).unloaded_cells == 1
    heads = HeadsSource(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 2.0]]),
                        np.array([False, True, True, False]), {"reference_time_s": 0.0})
    cov = measure(MPI.COMM_SELF, heads, volumes, 1.0)
    assert cov.summary() == {"source": "heads", "cells": 4, "unloaded_cells": 2, "unloaded_volume_fraction": 0.5,
                             "outside_cells": 2, "outside_volume_fraction": 0.5, "reference_time_s": 0.0}
    assert cov.line() == ("pfault: pore-pressure change in 2 of 4 cells (50 % of the volume); none in 2 (50 %), 2 of "
                          "them (50 % of the volume) outside the groundwater model (-pfault_heads_outside zero)")
    assert measure(MPI.COMM_SELF, TableSource(MaterialDrawdown([None]), np.zeros(4, int)), volumes, 1.0).line() is None
