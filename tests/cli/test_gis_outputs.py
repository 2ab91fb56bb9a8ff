"""The GIS layers of a run with -pfault_crs (pfault.post.gis), read back with GDAL/OGR (Debian's python3-gdal), as
QGIS reads them: one run of a small fissure box (a candidate surface that breaks to the land surface, stations, a
LOS raster) placed in UTM zone 50N, checked for

- every GeoTIFF's CRS and geotransform, its pixel centres equal to the site coordinates of the run's rasters
  (insar_los.nc, surface_maps.nc) to 1e-6 m and its values equal to theirs; the CF NetCDF files' grid mapping read
  by GDAL;
- the vector layers' CRS, and the fault and fissure traces equal to the fault plane's trace on the land surface
  (x = 375 m, y 0..100 m, plus the origin) to 1e-6 m; hazard zones covering the prone triangles;
- the stations' east/north/up series: mm, up = 1000 u_z, the horizontal turned by the meridian convergence pyproj
  gives at the station.
"""

import csv
import datetime as dt
import json
import os

import h5py
import numpy as np
import pytest

from conftest import run_scene
from pfault.errors import InputError
from pfault.io.insar import read_netcdf
from pfault.io.geopackage import Layer, write_geopackage
from pfault.io.insar_grid import locate_product_pixels
from pfault.post.gis import GisContext, face_attributes
from pfault.tools.insar_write import write_opera

gdal = pytest.importorskip("osgeo.gdal")
from osgeo import ogr, osr  # noqa: E402

ORIGIN = (500000.0, 3500000.0, 10.0)
SCENE = "config/hard/fissure_box.opts"
EXTRA = ["-pfault_box_cells", "8,4,5", "-pfault_fault_fissure_tensile_strength", "5*kPa",
         "-pfault_fault_fissure_cohesion", "10*kPa", "-pfault_time_steps", "4", "-pfault_crs", "EPSG:32650",
         "-pfault_mesh_origin", ",".join(f"{v:g}" for v in ORIGIN), "-pfault_start_date", "2015-01-01",
         "-pfault_insar_los", "-0.618,-0.110,0.778", "-pfault_insar_spacing", "25"]
STATIONS = "name,x,y,z\nA,500300,3500050,10\nB,500390,3500040,10\n"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("gis")
    (tmp / "st.csv").write_text(STATIONS)
    out = tmp / "run"
    proc, summary = run_scene(SCENE, out, extra=EXTRA + ["-pfault_stations", str(tmp / "st.csv")])
    assert summary["converged"] and "GIS files in gis/" in proc.stdout
    assert summary["georef"]["crs"]["epsg"] == 32650 and summary["georef"]["start_date"].startswith("2015-01-01")
    return out


def epsg_of(wkt):
    sr = osr.SpatialReference(wkt=wkt)
    sr.AutoIdentifyEPSG()
    return int(sr.GetAuthorityCode(None))


def centres(ds):
    gt = ds.GetGeoTransform()
    assert gt[2] == 0.0 and gt[4] == 0.0 and gt[5] < 0      # north up, no rotation
    x = gt[0] + gt[1] * (np.arange(ds.RasterXSize) + 0.5)
    y = gt[3] + gt[5] * (np.arange(ds.RasterYSize) + 0.5)
    return x, y, ds.GetRasterBand(1).ReadAsArray()


def test_geotiffs_carry_the_crs_and_the_site_coordinates(run_dir):
    los = read_netcdf(str(run_dir / "insar_los.nc"))
    with h5py.File(run_dir / "gis" / "surface_maps.nc") as nc:
        maps = {k: nc[k][-1] for k in ("subsidence", "horizontal_strain", "angular_distortion")}
        mx, my = nc["x"][()], nc["y"][()]
        assert str(nc["time"].attrs["units"]) == "seconds since 2015-01-01T00:00:00"
    cases = [("insar_los.tif", los["x"], los["y"], los["los_displacement"][-1]),
             ("insar_los_velocity.tif", los["x"], los["y"], los["los_velocity"][-1])]
    cases += [(f"{k}.tif", mx, my, v) for k, v in maps.items()]
    for name, x, y, values in cases:
        ds = gdal.Open(str(run_dir / "gis" / name))
        assert epsg_of(ds.GetProjection()) == 32650, name
        gx, gy, a = centres(ds)
        assert np.abs(gx - x).max() < 1e-6 and np.abs(gy - y[::-1]).max() < 1e-6, name
        assert np.allclose(np.fmod(gx - 12.5, 25.0), 0.0, atol=1e-6)    # aligned on multiples of the spacing
        assert np.array_equal(np.isnan(a), np.isnan(values[::-1])), name
        assert np.allclose(a[~np.isnan(a)], values[::-1][~np.isnan(a)], rtol=0, atol=1e-15), name
    # the land surface is covered: 400 m x 100 m in 25 m pixels, and subsidence is there
    assert maps["subsidence"].shape == (4, 16) and not np.isnan(maps["subsidence"]).any()
    assert np.nanmax(maps["subsidence"]) == pytest.approx(json.load(open(run_dir / "summary.json"))
                                                          ["max_subsidence_m"], rel=0.05)


@pytest.mark.parametrize("name,variable", [("insar_los.nc", "los_displacement"),
                                           ("gis/surface_maps.nc", "subsidence")])
def test_cf_netcdf_grid_mapping_read_by_gdal(run_dir, name, variable):
    ds = gdal.Open(f'NETCDF:"{run_dir / name}":{variable}')
    assert ds is not None and epsg_of(ds.GetProjection()) == 32650
    gt = ds.GetGeoTransform()
    assert gt[0] == pytest.approx(ORIGIN[0], abs=1e-6) and gt[1] == pytest.approx(25.0)


def layer(run_dir, name):
    src = ogr.Open(str(run_dir / "gis" / "pfault.gpkg"))
    lyr = src.GetLayerByName(name)
    assert lyr is not None, name
    assert epsg_of(lyr.GetSpatialRef().ExportToWkt()) == 32650
    feats = [(f.GetGeometryRef().Clone(), f.items()) for f in lyr]
    return feats


def test_trace_layers_are_the_fault_trace_on_the_land_surface(run_dir):
    for name in ("fault_traces", "fissure_traces"):
        feats = layer(run_dir, name)
        pts = np.array([g.GetPoints() for g, _ in feats])           # (n, 2, 2) segments
        assert np.abs(pts[:, :, 0] - (ORIGIN[0] + 375.0)).max() < 1e-6
        y = np.sort(pts[:, :, 1], axis=1) - ORIGIN[1]
        order = np.argsort(y[:, 0])
        y = y[order]
        # the segments tile y = 0 .. 100 m without gap or overlap
        assert y[0, 0] == pytest.approx(0, abs=1e-6) and y[-1, 1] == pytest.approx(100, abs=1e-6)
        assert np.abs(y[1:, 0] - y[:-1, 1]).max() < 1e-6
    fissures = layer(run_dir, "fissure_traces")
    assert all(a["fault"] == "fissure" and a["break_time_s"] > 0 for _, a in fissures)
    start = dt.datetime(2015, 1, 1, tzinfo=dt.timezone.utc)
    for _, a in fissures:
        assert a["break_date"] == (start + dt.timedelta(seconds=a["break_time_s"])).date().isoformat()
    states = {a["state"] for _, a in layer(run_dir, "fault_traces")}
    assert states <= {"stick", "slip", "open"}


def test_hazard_zones_cover_the_prone_land_surface(run_dir):
    with h5py.File(run_dir / "surface.h5") as f:
        pts, tris = f["mesh/points"][...], f["mesh/cells"][...]
        strain = f["steps"][sorted(f["steps"])[-1]]["horizontal_strain"][...]
    prone = strain > 2e-4
    assert prone.any()
    p = pts[tris[prone]][:, :, :2] + np.array(ORIGIN[:2])
    area = 0.5 * np.abs(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    zones = layer(run_dir, "hazard_zones")
    assert sum(g.GetArea() for g, _ in zones) == pytest.approx(area.sum(), rel=1e-9)
    assert sum(a["area_m2"] for _, a in zones) == pytest.approx(area.sum(), rel=1e-9)
    for c in p.mean(axis=1):
        pt = ogr.CreateGeometryFromWkt(f"POINT ({c[0]!r} {c[1]!r})")
        assert sum(g.Contains(pt) for g, _ in zones) == 1
    assert max(a["max_horizontal_strain"] for _, a in zones) == pytest.approx(strain.max(), rel=1e-12)


def test_stations_as_gnss_east_north_up_series(run_dir):
    from pyproj import CRS, Proj, Transformer
    with open(run_dir / "station_displacement.csv", newline="") as fh:
        model = list(csv.DictReader(fh))
    with open(run_dir / "gis" / "stations_enu.csv", newline="") as fh:
        enu = list(csv.DictReader(fh))
    assert list(enu[0]) == ["station", "date", "decimal_year", "time_s", "east_mm", "north_mm", "up_mm"]
    assert len(enu) == len(model)
    crs = CRS.from_epsg(32650)
    to_geo = Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    xyz = {"A": (500300.0, 3500050.0), "B": (500390.0, 3500040.0)}
    enu = {(e["station"], float(e["time_s"])): e for e in enu}     # one series per station, in time order
    for m in model:
        e = enu[(m["name"], float(m["time_s"]))]
        ux, uy, uz = (float(m[k]) for k in ("ux_m", "uy_m", "uz_m"))
        assert float(e["up_mm"]) == pytest.approx(1e3 * uz, abs=1e-4)
        lon, lat = to_geo.transform(*xyz[m["name"]])
        # the convergence gamma: grid north is gamma clockwise from true north (east of the central meridian,
        # gamma > 0), so true north is (-sin gamma, cos gamma) in the grid
        gamma = np.deg2rad(Proj(crs).get_factors(lon, lat).meridian_convergence)
        assert gamma > 0
        east = np.cos(gamma) * ux + np.sin(gamma) * uy
        north = -np.sin(gamma) * ux + np.cos(gamma) * uy
        assert float(e["east_mm"]) == pytest.approx(1e3 * east, abs=6e-5)
        assert float(e["north_mm"]) == pytest.approx(1e3 * north, abs=6e-5)
        when = dt.datetime(2015, 1, 1) + dt.timedelta(seconds=float(m["time_s"]))
        assert e["date"] == when.date().isoformat()
    pts = layer(run_dir, "stations")
    assert [(g.GetX(), g.GetY()) for g, _ in pts] == [xyz["A"], xyz["B"]]


def test_los_raster_on_an_insar_products_pixels(run_dir, tmp_path):
    """-pfault_insar_grid: an OPERA-like product whose pixels are the regular raster's plus a margin gives the same
    LOS there (its per-pixel LOS equal to the scene's), no-data off the land surface, and the product's CRS."""
    from pyproj import CRS
    regular = read_netcdf(str(run_dir / "insar_los.nc"))
    x = np.r_[regular["x"][0] - 25.0, regular["x"], regular["x"][-1] + 25.0]
    y = np.r_[regular["y"][0] - 25.0, regular["y"], regular["y"][-1] + 25.0]
    los = np.broadcast_to(regular["los"], (len(y), len(x), 3))
    when = dt.datetime(2016, 1, 1, tzinfo=dt.timezone.utc)
    product = write_opera(str(tmp_path / "grid.nc"), x, y, CRS.from_epsg(32650), [when], [when],
                          np.zeros((1, len(y), len(x))), los)
    (tmp_path / "st.csv").write_text(STATIONS)
    extra = [e for e in EXTRA if e not in ("-pfault_insar_los", "-0.618,-0.110,0.778")]
    _, summary = run_scene(SCENE, tmp_path / "run", extra=extra + ["-pfault_insar_grid", product, "-pfault_gis",
                                                                    "false"])
    assert summary["converged"] and not (tmp_path / "run" / "gis").exists()
    got = read_netcdf(str(tmp_path / "run" / "insar_los.nc"))
    assert np.array_equal(got["x"], x) and np.array_equal(got["y"], y) and got["los"].shape[1] == 3
    inner = got["los_displacement"][:, 1:-1, 1:-1]
    # the same to the float32 of the product's LOS layers (OPERA stores them so)
    assert np.allclose(inner, regular["los_displacement"], rtol=1e-6, atol=1e-9)
    edge = np.ones(got["los_displacement"].shape[1:], bool)
    edge[1:-1, 1:-1] = False
    assert np.isnan(got["los_displacement"][:, edge]).all()
    assert CRS.from_wkt(got["grid_mapping"]["crs_wkt"]).to_epsg() == 32650


def test_product_and_scene_crs_must_both_be_given(tmp_path):
    from pyproj import CRS
    when = dt.datetime(2016, 1, 1, tzinfo=dt.timezone.utc)
    x = y = np.array([25.0, 75.0])
    product = write_opera(str(tmp_path / "p.nc"), x, y, CRS.from_epsg(32650), [when], [when], np.zeros((1, 2, 2)))
    with pytest.raises(InputError, match="the product is in WGS 84 / UTM zone 50N but the scene has no -pfault_crs"):
        locate_product_pixels(None, "top", product, (0, 0, 0), None, np.array([0.0, 0.0, 1.0]))


# -- soils that remember and margins to failure ---------------------------------------------------------------------
SOIL = ["-pfault_box_cells", "8,4,5", "-pfault_time_steps", "4", "-pfault_geostatic", "true", "-pfault_water_table",
        "-2", "-pfault_material_clay_density", "1900", "-pfault_material_sand_density", "2000",
        "-pfault_material_rock_density", "2400", "-pfault_material_clay_compression_index", "0.3",
        "-pfault_material_clay_recompression_index", "0.04", "-pfault_material_clay_void_ratio", "0.9",
        "-pfault_material_clay_head_drawdown", "0:0,10*year:10", "-pfault_crs", "EPSG:32650",
        "-pfault_mesh_origin", ",".join(f"{v:g}" for v in ORIGIN), "-pfault_map_spacing", "25"]


@pytest.fixture(scope="module")
def soil_run(tmp_path_factory):
    """The fissure box (its plane a pre-existing fault) with its clay given compression indices (Cc 0.3, Cr 0.04)
    and drawn down 10 m besides the sand's 20 m, in 4 steps, geostatic start: 1,080 tetrahedra, ~1 s."""
    tmp = tmp_path_factory.mktemp("gis_soil")
    with open(SCENE) as fh:
        text = fh.read()
    assert "-pfault_material_clay_young_modulus 8*MPa\n" in text
    (tmp / "soil.opts").write_text(text.replace("-pfault_material_clay_young_modulus 8*MPa\n", ""))
    _, summary = run_scene(str(tmp / "soil.opts"), tmp / "run", extra=SOIL)
    assert summary["converged"] and summary["soils"]["clay"]["cells_virgin"] == 216
    return tmp / "run", summary


def p1_at(points, tris, values, x, y):
    """The P1 interpolant of ``values`` at the land surface's points, at the site points (x, y): barycentric
    coordinates in the first triangle that holds each."""
    p = points[tris][:, :, :2]
    d = np.stack([x, y], axis=1)[:, None, :] - p[None, :, 2, :]                          # (m, t, 2)
    a = np.stack([p[:, 0] - p[:, 2], p[:, 1] - p[:, 2]], axis=2)                          # (t, 2, 2): columns
    lam = np.einsum("tij,mtj->mti", np.linalg.inv(a), d)
    lam = np.concatenate([lam, 1 - lam.sum(axis=2, keepdims=True)], axis=2)
    inside = (lam >= -1e-12).all(axis=2)
    assert inside.any(axis=1).all()
    k = inside.argmax(axis=1)
    m = np.arange(len(x))
    return np.einsum("mk,mk->m", lam[m, k], values[tris[k]])


def test_soil_geotiffs_are_the_land_surface_point_data(soil_run):
    """critical_head_clay.tif, head_margin_clay.tif, subsidence_inelastic.tif, subsidence_elastic.tif: the scene's
    CRS, the grid of subsidence.tif (25 m pixels from the origin), every pixel centre the P1 interpolant of
    surface.h5's last output time at that site point to 1e-9 relative; inelastic plus elastic is the subsidence."""
    run, _ = soil_run
    with h5py.File(run / "surface.h5") as f:
        pts, tris = f["mesh/points"][...] + np.array(ORIGIN), f["mesh/cells"][...].astype(np.int64)
        last = f["steps"][sorted(f["steps"])[-1]]
        data = {k: last[k][...] for k in ("critical_head_clay", "head_margin_clay", "subsidence_inelastic",
                                          "subsidence_elastic")}
    reference = gdal.Open(str(run / "gis" / "subsidence.tif"))
    band = {}
    for name, at_points in data.items():
        ds = gdal.Open(str(run / "gis" / f"{name}.tif"))
        assert epsg_of(ds.GetProjection()) == 32650, name
        assert ds.GetGeoTransform() == (ORIGIN[0], 25.0, 0.0, ORIGIN[1] + 100.0, 0.0, -25.0), name
        assert ds.GetGeoTransform() == reference.GetGeoTransform()
        assert ds.GetRasterBand(1).GetMetadata()["units"] == "m"
        x, y, a = centres(ds)
        assert a.shape == (4, 16) and not np.isnan(a).any()
        gx, gy = np.meshgrid(x, y)
        expected = p1_at(pts, tris, at_points, gx.ravel(), gy.ravel()).reshape(a.shape)
        np.testing.assert_allclose(a, expected, rtol=1e-9, atol=0, err_msg=name)
        band[name] = a
    # the clay's critical head varies across the land surface (-10.25 .. -9.69 m: 10 m drawn down, compacting)
    assert band["critical_head_clay"].min() < -10.2 and band["critical_head_clay"].max() > -9.8
    total = reference.GetRasterBand(1).ReadAsArray()
    np.testing.assert_allclose(band["subsidence_inelastic"] + band["subsidence_elastic"], total, rtol=1e-12,
                               atol=1e-15)


def test_fault_layers_carry_the_margins_to_failure(soil_run):
    """fault_faces: every fault face as a 3-D triangle with fault.h5's margin and mode at the last output time;
    the face with the smallest margin is summary.json's (its margin, mode, row and centroid); fault_traces carry
    their faces' margins."""
    run, summary = soil_run
    m = summary["faults"]["fissure"]["margin"]
    with h5py.File(run / "fault.h5") as f:
        last = f["steps"][sorted(f["steps"])[-1]]
        margin, mode = last["margin_drawdown_m"][...], last["margin_mode"][...]
    faces = layer(run, "fault_faces")
    assert len(faces) == len(margin) == 16
    got = np.array([a["margin_drawdown_m"] for _, a in faces])
    failed = got == 0.0                                     # faces slipping now: no further drawdown needed
    assert np.array_equal(got, margin) and m["faces_failed"] == failed.sum() == 2
    assert [a["margin_mode"] for _, a in faces] == [{0: "slip", 1: "open", 2: "break"}[c] for c in mode]
    g, a = faces[int(np.argmin(np.where(failed, np.inf, got)))]   # summary.json's smallest: of the faces not failed
    assert a["margin_drawdown_m"] == pytest.approx(m["min_drawdown_m"], rel=1e-12)
    assert a["margin_drawdown_m"] == pytest.approx(1.614, rel=1e-3)
    assert a["face"] == m["min_face"] and a["margin_mode"] == m["min_mode"] == "slip"
    ring = np.array(g.GetGeometryRef(0).GetPoints())
    assert ring.shape == (4, 3) and np.abs(ring[:3].mean(axis=0) - m["min_xyz_m"]).max() < 1e-6
    assert np.abs(ring[:, 0] - (ORIGIN[0] + 375.0)).max() < 1e-6
    traces = layer(run, "fault_traces")
    assert len(traces) == 4
    for _, t in traces:
        assert t["margin_drawdown_m"] == margin[t["face"]] and t["margin_mode"] == "slip"


def test_margins_not_computed_or_never_reached_are_null(tmp_path):
    """A face no further drawdown fails (inf, mode -1) has a NULL margin and mode ``never``; one whose margin's
    solve failed (NaN) and a run without margins (no margin fields in fault.h5) NULL margin and mode."""
    from pyproj import CRS
    ctx = GisContext(CRS.from_epsg(32650), None, np.zeros(3), None, 2e-4, ["f"])
    tri = [np.array([[0.0, 0.0, 0.0], [1.0, 0.0, -1.0], [0.0, 1.0, -2.0]])]
    with_margins = face_attributes({"margin_drawdown_m": np.array([1.5, np.inf, np.nan]),
                                    "margin_mode": np.array([1, -1, 0])}, 3, ctx, 1.0)
    without = face_attributes({}, 2, ctx, 1.0)
    path = write_geopackage(str(tmp_path / "m.gpkg"), ctx.crs,
                            [Layer("a", "POLYGON", [tri] * 3, with_margins, dims=3),
                             Layer("b", "POLYGON", [tri] * 2, without, dims=3)])
    src = ogr.Open(path)
    got = {name: [f.items() for f in src.GetLayerByName(name)] for name in ("a", "b")}
    assert [(a["margin_drawdown_m"], a["margin_mode"]) for a in got["a"]] == [(1.5, "open"), (None, "never"),
                                                                             (None, None)]
    assert [(a["margin_drawdown_m"], a["margin_mode"]) for a in got["b"]] == [(None, None)] * 2
    feature = src.GetLayerByName("a").GetFeature(1)         # held: its geometry is a reference into it
    geom = feature.GetGeometryRef()
    assert geom.Is3D() and geom.GetGeometryRef(0).GetPoints()[:3] == [tuple(p) for p in tri[0]]
