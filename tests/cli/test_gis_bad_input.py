"""Bad GIS and InSAR inputs from the command line: exit code 1, one line naming the option or file and the fix,
no traceback, nothing written (pfault runs: no output directory; calibrations: no output directory)."""

import datetime as dt

import h5py
import numpy as np
import pytest
from pyproj import CRS

from conftest import OEDOMETER
from conftest import run as run_python
from pfault.tools.insar_write import write_opera

SITE = "config/site_example/site.opts"
WHEN = [dt.datetime(2016, 1, 1, tzinfo=dt.timezone.utc), dt.datetime(2017, 1, 1, tzinfo=dt.timezone.utc)]


def run(args):
    proc = run_python(args, timeout=120, check=False)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and "Warning" not in ln and "warn" not in ln]
    return proc.returncode, lines, proc.stderr


def product(tmp_path, drop=None):
    x, y = 500025.0 + 50 * np.arange(40), 3500025.0 + 50 * np.arange(20)
    path = write_opera(str(tmp_path / f"p_{drop}.nc"), x, y, CRS.from_epsg(32650), WHEN, [WHEN[0]],
                       np.zeros((2, 20, 40)))
    if drop:
        with h5py.File(path, "r+") as f:
            del f[drop]
    return path


@pytest.mark.parametrize("extra,words", [
    (["-pfault_crs", "EPSG:4326"], "-pfault_crs EPSG:4326: 'WGS 84' is not a projected CRS"),
    (["-pfault_crs", "NOPE"], "-pfault_crs NOPE: not a coordinate reference system PROJ knows"),
    (["-pfault_start_date", "2015-02-30"], "-pfault_start_date 2015-02-30: not an ISO 8601 date"),
    (["-pfault_map_spacing", "-5"], "-pfault_map_spacing -5: the pixel size must be positive"),
])
def test_bad_run_options(tmp_path, extra, words):
    out = tmp_path / "out"
    code, lines, err = run(["-m", "pfault", OEDOMETER, "-pfault_output_dir", str(out), *extra])
    assert code == 1 and len(lines) == 1 and words in lines[0] and "Traceback" not in err, err
    assert not out.exists()


def test_bad_insar_calibrations(tmp_path):
    params = tmp_path / "params.csv"
    params.write_text("name,option,start,lower,upper\nE,-pfault_material_sand_young_modulus,20*MPa,1*MPa,100*MPa\n")
    base = ["-m", "pfault.calibrate", SITE, "--parameters", str(params), "--output", str(tmp_path / "fit")]
    cases = [
        (["--insar", product(tmp_path, drop="reference_time"), "--insar-sigma", "5*mm"],
         "no 'reference_time': InSAR displacements are relative to a reference date"),
        (["--insar", product(tmp_path)], "--insar-sigma: give the standard deviation of an InSAR value"),
        (["--insar", product(tmp_path), "--insar-sigma", "5*mm", "--insar-reference", "north"],
         "--insar-reference north: give 'offset'"),
        ([], "give --observations (station series) or --insar"),
    ]
    for extra, words in cases:
        code, lines, err = run(base + extra)
        assert code == 1 and len(lines) == 1 and words in lines[0] and "Traceback" not in err, (extra, err)
        assert not (tmp_path / "fit").exists()
    twin = ["-m", "pfault.calibrate", "config/twin/twin.opts", "--parameters", str(params), "--insar",
            product(tmp_path), "--insar-sigma", "5*mm", "--output", str(tmp_path / "fit")]
    code, lines, err = run(twin)
    assert code == 1 and "has no -pfault_start_date, so the product's dates cannot be placed" in lines[0], err
