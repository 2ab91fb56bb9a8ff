"""InSAR products read in-process (pfault.io.insar_input): OPERA DISP-S1's layout and MintPy's give the same
pixels, dates, reference and values; an axis in either order is read the same; NaN and masked values stay NaN
(skipped, never filled); each bad form (no reference date, values not on the axes, an axis out of order, no value
at all, dates out of order) is one line naming the file and the fix. The model's LOS in time (insar_fit._at)."""

import datetime as dt

import h5py
import numpy as np
import pytest
from pyproj import CRS

from pfault.errors import InputError
from pfault.io.insar_input import read_insar_product
from pfault.tools.insar_fit import _at, parse_reference
from pfault.tools.insar_write import write_mintpy, write_opera

UTC = dt.timezone.utc
DATES = [dt.datetime(2016 + k, 3, 1, tzinfo=UTC) for k in range(4)]
REF = dt.datetime(2015, 6, 1, tzinfo=UTC)
X, Y = 500025.0 + 50 * np.arange(5), 3500025.0 + 50 * np.arange(3)


def values():
    v = np.arange(4 * 3 * 5, dtype=float).reshape(4, 3, 5) * 1e-3
    v[1, 2, 3] = np.nan
    return v


@pytest.fixture
def opera(tmp_path):
    los = np.broadcast_to([0.6, -0.1, np.sqrt(1 - 0.37)], (3, 5, 3))
    return write_opera(str(tmp_path / "disp.nc"), X, Y, CRS.from_epsg(32650), DATES, [REF], values(), los)


def test_opera_and_mintpy_read_alike(opera, tmp_path):
    a = read_insar_product(opera)
    b = read_insar_product(write_mintpy(str(tmp_path / "timeseries.h5"), X, Y, 32650, DATES, REF, values()))
    for p in (a, b):
        assert np.allclose(p.x, X) and np.allclose(p.y, Y) and p.crs.to_epsg() == 32650
        assert p.dates == DATES and p.reference == [REF] * 4
        assert np.array_equal(np.isnan(p.values), np.isnan(values()))
        assert np.allclose(p.values[~np.isnan(p.values)], values()[~np.isnan(values())], atol=1e-7)
    assert a.los.shape == (3, 5, 3) and np.allclose(np.linalg.norm(a.los, axis=-1), 1) and b.los is None


def test_axes_in_either_order_and_masks(opera):
    with h5py.File(opera, "r+") as f:          # y stored north first: turn it round, values with it
        f["y"][...] = f["y"][()][::-1]
        f["displacement"][...] = f["displacement"][()][:, ::-1]
        f["los_east"][...] = f["los_east"][()][::-1]
        f.create_dataset("recommended_mask", data=np.ones((3, 5), np.uint8))
        f["recommended_mask"][0, 0] = 0
    p = read_insar_product(opera)
    expect = values()
    expect[:, 0, 0] = np.nan                    # the masked pixel (the file now south first: south-west), every date
    assert np.allclose(p.y, Y) and np.array_equal(np.isnan(p.values), np.isnan(expect))


@pytest.mark.parametrize("change,words", [
    (lambda f: f.__delitem__("reference_time"), "no 'reference_time': InSAR displacements are relative to a "
                                                 "reference date"),
    (lambda f: f["x"].__setitem__(2, 1.0), "its x coordinates are not in order"),
    (lambda f: f["displacement"].__setitem__(Ellipsis, np.nan), "no pixel has a value"),
    (lambda f: f["time"].__setitem__(slice(None), f["time"][()][::-1]), "its dates are not increasing"),
    (lambda f: f["time"].attrs.__setitem__("units", "days"), "not CF's '<seconds|days> since <date>'"),
    (lambda f: f["displacement"].attrs.__setitem__("units", "radians"), "'displacement' is in 'radians'"),
])
def test_bad_products_are_one_line(opera, change, words):
    with h5py.File(opera, "r+") as f:
        change(f)
    with pytest.raises(InputError) as err:
        read_insar_product(opera)
    line = str(err.value)
    assert "\n" not in line and line.startswith(f"--insar {opera}") and words in line, line


def test_wrong_shape_and_mintpy_without_reference(tmp_path):
    path = write_mintpy(str(tmp_path / "ts.h5"), X, Y, 32650, DATES, REF, values())
    with h5py.File(path, "r+") as f:
        del f.attrs["REF_DATE"]
    with pytest.raises(InputError, match="no REF_DATE attribute: InSAR displacements are relative to a reference"):
        read_insar_product(path)
    bad = str(tmp_path / "bad.nc")
    write_opera(bad, X, Y, CRS.from_epsg(32650), DATES, [REF], values())
    with h5py.File(bad, "r+") as f:
        del f["x"]
        f.create_dataset("x", data=X[:4])
    with pytest.raises(InputError, match=r"'displacement' is \(4, 3, 5\), but \(time, y, x\) asks for \(nt, 3, 4\)"):
        read_insar_product(bad)


def test_model_in_time_and_reference_option():
    times = np.array([0.0, 10.0, 20.0])
    maps = np.array([0.0, 1.0, 4.0])[:, None, None] * np.ones((3, 2, 2))
    got = _at(times, maps, np.array([-5.0, 0.0, 5.0, 15.0, 20.0]))[:, 0, 0]
    assert np.allclose(got, [0.0, 0.0, 0.5, 2.5, 4.0])          # at rest before time 0, linear between outputs
    assert parse_reference("offset") is None and parse_reference("500100,3500050") == (500100.0, 3500050.0)
    with pytest.raises(InputError, match="--insar-reference 12: give 'offset'"):
        parse_reference("12")
