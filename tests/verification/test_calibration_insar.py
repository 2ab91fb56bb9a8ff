"""Twin experiment of python -m pfault.calibrate --insar (studies/insar_twin.py): the clay's and the sand's moduli of
the example site fitted to a synthetic OPERA DISP-S1-like product (5 mm noise, a random offset per date, 5 % of the
values missing, a per-pixel line of sight) from a start a factor 2 away: within two standard errors of the truth, the
residual variance near 1, the offsets recovered, the fit's files readable (GDAL reads the residual's CRS)."""

import json

import h5py
import numpy as np

from studies import insar_twin as twin


def test_moduli_from_an_opera_like_insar_series(tmp_path):
    proc, offsets = twin.calibrate(str(tmp_path), workers=2)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = tmp_path / "fit"
    s = json.load(open(out / "calibration.json"))
    assert s["converged"] and s["failed_runs"] == 0 and s["runs"] <= 25
    for name, true in twin.TRUE.items():
        f = s["fitted"][name]
        assert abs(np.log10(f["value"] / true)) < 2 * f["standard_error_log10"], (name, f)
        assert 1e-4 < f["standard_error"] / true < 0.02, (name, f)
    insar = s["insar"]
    assert insar["values_used"] > 6000 and insar["values_skipped_no_data"] > 0
    assert s["degrees_of_freedom"] == insar["values_used"] - 2 - len(twin.DATES)       # one offset per date
    assert 0.9 < s["residual_variance"] < 1.1                  # 5 mm noise, sigma 5 mm
    # the fitted offsets (model - observed) undo the offsets added, to the noise of a date's mean
    assert np.abs(np.array(insar["offsets_m"]) + offsets).max() < 1e-3
    with h5py.File(out / "insar_fit.nc") as nc:
        model, observed, residual = (nc[k][()] for k in ("model", "observed", "residual"))
        used = np.isfinite(residual)
        assert used.sum() == insar["values_used"]
        assert np.allclose((model - observed)[used], residual[used], atol=1e-12)
        assert abs(np.sqrt(np.mean(residual[used] ** 2)) / twin.SIGMA - 1) < 0.1
    from osgeo import gdal, osr
    ds = gdal.Open(str(out / "insar_residual.tif"))
    sr = osr.SpatialReference(wkt=ds.GetProjection())
    assert sr.GetAuthorityCode(None) == "32650" and ds.GetGeoTransform()[1] == 50.0
