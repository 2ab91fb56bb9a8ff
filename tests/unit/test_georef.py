"""-pfault_crs and -pfault_start_date (pfault.georef), in-process: every accepted form gives the same CRS, every
bad form is one line naming the option and the fix; the CF grid mapping round-trips; true east/north at a
point of a UTM zone."""

import datetime as dt

import numpy as np
import pytest
from pyproj import CRS

from pfault.errors import InputError
from pfault.georef import (Transform, cf_grid_mapping, crs_from_cf, decimal_year, parse_crs, parse_date,
                           true_east_north)


def test_accepted_forms_name_the_same_crs(tmp_path):
    utm = CRS.from_epsg(32650)
    (tmp_path / "site.prj").write_text(utm.to_wkt("WKT1_ESRI"))
    scene = tmp_path / "scene.opts"
    for text in ("EPSG:32650", "32650", "epsg:32650", utm.to_wkt(), str(tmp_path / "site.prj")):
        assert parse_crs(text).equals(utm, ignore_axis_order=True), text
    assert parse_crs("site.prj", scene_file=str(scene)).equals(utm, ignore_axis_order=True)   # beside the scene
    compound = CRS.from_user_input("EPSG:32650+5773")                 # UTM + EGM96 height: the horizontal part
    assert parse_crs(compound.to_wkt()).equals(utm, ignore_axis_order=True)


@pytest.mark.parametrize("text,words", [
    ("EPSG:4326", "not a projected CRS"),
    ("EPSG:2227", "has axes in US survey foot"),
    ("EPSG:99999999", "not a coordinate reference system PROJ knows"),
    ("UTM50", "not a coordinate reference system PROJ knows"),
])
def test_bad_crs_is_one_line_with_the_fix(text, words):
    with pytest.raises(InputError) as err:
        parse_crs(text)
    line = str(err.value)
    assert "\n" not in line and line.startswith(f"-pfault_crs {text}") and words in line
    assert "EPSG:32650" in line or "metres" in line


@pytest.mark.parametrize("text", ["2015-13-01", "01/02/2015", "yesterday"])
def test_bad_start_date(text):
    with pytest.raises(InputError, match=r"-pfault_start_date .*: not an ISO 8601 date; give the date as YYYY-MM-DD"):
        parse_date(text, "-pfault_start_date")


def test_dates_are_utc_and_decimal_years():
    assert parse_date("2015-01-01", "x") == dt.datetime(2015, 1, 1, tzinfo=dt.timezone.utc)
    assert parse_date("2015-07-02T12:00:00Z", "x").tzinfo == dt.timezone.utc
    assert decimal_year(parse_date("2016-07-02", "x")) == pytest.approx(2016 + 183 / 366)


def test_cf_grid_mapping_round_trips_and_transform_matches_pyproj():
    utm, gk = CRS.from_epsg(32650), CRS.from_epsg(4547)      # CGCS2000 / 3-degree Gauss-Kruger CM 114E
    for crs in (utm, gk):
        attrs = cf_grid_mapping(crs)
        assert crs_from_cf(attrs, "f").equals(crs) and attrs["crs_wkt"] == attrs["spatial_ref"]
        assert crs_from_cf({"wkt": crs.to_wkt()}, "f").equals(crs)          # MODFLOW 6's mesh files
    assert crs_from_cf({"units": "m"}, "f") is None
    x, y = np.array([500000.0, 520000.0]), np.array([3500000.0, 3510000.0])
    from pyproj import Transformer
    ref = Transformer.from_crs(utm, gk, always_xy=True).transform(x, y)
    got = Transform(utm, gk)(x, y)
    assert np.allclose(got, ref, rtol=0, atol=1e-9) and Transform(utm, None)(x, y)[0] is not None


def test_true_north_at_the_central_meridian_is_grid_north():
    crs = CRS.from_epsg(32650)
    east, north = true_east_north(crs, np.array([500000.0, 600000.0]), np.array([3500000.0, 3500000.0]))
    assert np.allclose(north[0], [0, 1], atol=1e-9) and np.allclose(east[0], [1, 0], atol=1e-9)
    assert north[1, 0] < -1e-3                                 # east of it, true north leans west of grid north
    assert np.allclose(np.einsum("ij,ij->i", east, north), 0, atol=1e-12)
