"""Twin experiment of ``python -m pfault.calibrate --insar`` on the example site (config/site_example/site.opts):
a synthetic OPERA DISP-S1-like product from a run at known moduli of the clay and the sand (uniform), on 50 m
pixels reaching beyond the land surface, with a per-pixel line of sight (incidence 33 to 43 degrees across the frame),
nine yearly dates referred to mid-2015, Gaussian noise of 5 mm, a random offset per date (20 mm) and 5 % of the
values missing; then the two moduli fitted from a start a factor 2 away, the offsets eliminated date by date.
Used by benchmarks/insar_twin.py and tests/verification/test_calibration_insar.py."""

from __future__ import annotations

import csv
import datetime as dt
import os

import numpy as np
from pyproj import CRS

from pfault.tools.insar_fit import _at
from pfault.tools.insar_write import write_opera
from pfault.tools.runs import Run, run_captured, run_pfault

from . import REPO

SCENE = "config/site_example/site.opts"
CRS_SITE = CRS.from_epsg(32650)
START = dt.datetime(2015, 1, 1, tzinfo=dt.timezone.utc)
REFERENCE = dt.datetime(2015, 7, 1, tzinfo=dt.timezone.utc)
DATES = [dt.datetime(year, 1, 1, tzinfo=dt.timezone.utc) for year in range(2016, 2025)]
TRUE = {"E_clay": 5e6, "E_sand": 30e6}
START_VALUES = {"E_clay": 10e6, "E_sand": 15e6}
BOUNDS = {"E_clay": (0.5e6, 100e6), "E_sand": (2e6, 400e6)}
OPTIONS = {"E_clay": "-pfault_material_clay_young_modulus", "E_sand": "-pfault_material_sand_young_modulus"}
SIGMA, OFFSET_SIGMA, MISSING = 0.005, 0.020, 0.05
SEED = 20260115
RUN_TIMEOUT = 300


def pixels():
    """50 m pixel centres over the site and one pixel beyond it on each side (site coordinates, UTM 50N)."""
    return 500000.0 - 25.0 + 50.0 * np.arange(42), 3500000.0 - 25.0 + 50.0 * np.arange(22)


def line_of_sight(x, y):
    """(ny, nx, 3) unit vectors from the ground to an ascending satellite looking east-north-east: incidence from
    33 degrees (west edge) to 43 (east edge)."""
    inc = np.deg2rad(np.interp(x, [x[0], x[-1]], [33.0, 43.0]))[None, :] * np.ones((len(y), 1))
    az = np.deg2rad(-100.0)                       # horizontal direction to the satellite: west, a little south
    return np.stack([np.sin(inc) * np.sin(az), np.sin(inc) * np.cos(az), np.cos(inc)], axis=-1)


def write_product(path, values, x, y):
    return write_opera(path, x, y, CRS_SITE, DATES, [REFERENCE], values, line_of_sight(x, y))


def truth(workdir):
    """The model's LOS at the product's pixels and dates, relative to the reference date, at the true moduli (NaN
    off the land surface), from a run on a template of the product's grid."""
    x, y = pixels()
    template = write_product(os.path.join(workdir, "grid.nc"), np.zeros((len(DATES), len(y), len(x))), x, y)
    overrides = {OPTIONS[k][1:]: repr(v) for k, v in TRUE.items()}
    overrides["pfault_insar_grid"] = template
    out = os.path.join(workdir, "truth")
    result = run_pfault(Run(SCENE, out, overrides, timeout=RUN_TIMEOUT), cwd=REPO, env=None)
    assert result.ok, result.error
    from pfault.io.insar import read_netcdf
    run = read_netcdf(os.path.join(out, "insar_los.nc"))
    seconds = np.array([(d - START).total_seconds() for d in DATES])
    ref = np.full(len(DATES), (REFERENCE - START).total_seconds())
    return _at(run["time"], run["los_displacement"], seconds) - _at(run["time"], run["los_displacement"], ref)


def observed(workdir, noise=True):
    """The synthetic product (its path) and the offsets added to each date."""
    x, y = pixels()
    model = truth(workdir)
    rng = np.random.default_rng(SEED)
    offsets = OFFSET_SIGMA * rng.standard_normal(len(DATES)) if noise else np.zeros(len(DATES))
    values = model + offsets[:, None, None]
    if noise:
        values += SIGMA * rng.standard_normal(values.shape)
        values[rng.random(values.shape) < MISSING] = np.nan
    values[:, :, 0] = np.nan                         # the west column has no value (off the land surface anyway)
    return write_product(os.path.join(workdir, "disp_s1.nc"), values, x, y), offsets


def write_parameters(path):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "option", "start", "lower", "upper", "transform", "value"])
        for name, option in OPTIONS.items():
            w.writerow([name, option, repr(START_VALUES[name]), *map(repr, BOUNDS[name]), "log", ""])


def calibrate(workdir, workers=2, noise=True, timeout=900):
    """Writes the product and the parameters into workdir and fits the moduli; (CompletedProcess, offsets)."""
    os.makedirs(workdir, exist_ok=True)
    params = os.path.join(workdir, "parameters.csv")
    write_parameters(params)
    product, offsets = observed(workdir, noise)
    args = ["-m", "pfault.calibrate", SCENE, "--parameters", params, "--insar", product,
            "--insar-sigma", f"{SIGMA}", "--workers", str(workers), "--output", os.path.join(workdir, "fit"),
            "--timeout", str(RUN_TIMEOUT)]
    proc = run_captured(args, cwd=REPO, timeout=timeout)
    return proc, offsets
