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
from pfault.io.insar_grid import locate_product_pixels
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
