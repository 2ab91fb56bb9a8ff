"""Twin experiment of python -m pfault.calibrate (studies/calibration_twin.py, config/twin/twin.opts): the two
Young's moduli and the pumping rate of a clay-over-sand box drained by a well, fitted from a start a factor 2
away to the stations of a run at known values: exactly recovered from exact observations, within two standard
errors from observations with 2 % Gaussian noise, in at most 30 forward runs, two side by side."""

import csv
import json
import os

import numpy as np
import pytest

from conftest import run_scene
from studies import calibration_twin as twin
from pfault.post.rundir import read_station_series

DAYS = [15, 30, 60, 90, 120]


def fitted(out):
    with open(os.path.join(out, "calibration.json")) as fh:
        return json.load(fh)


@pytest.mark.parametrize("noise", [False, True], ids=["exact", "noisy"])
def test_twin_experiment_recovers_the_moduli_and_the_pumping_rate(tmp_path, noise):
    proc = twin.calibrate(str(tmp_path), DAYS, workers=2, noise=noise)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = tmp_path / "fit"
    s = fitted(out)
    assert s["converged"] and s["failed_runs"] == 0 and s["runs"] <= 30
    assert s["observations"] == 10 * len(DAYS) and s["degrees_of_freedom"] == s["observations"] - 3
    for name, true in twin.TRUE.items():
        f = s["fitted"][name]
        if noise:
            # within two standard errors, in the fitted variable (log10 for the moduli)
            if "standard_error_log10" in f:
                assert abs(np.log10(f["value"] / true)) < 2 * f["standard_error_log10"], (name, f)
            else:
                assert abs(f["value"] - true) < 2 * f["standard_error"], (name, f)
            assert 0.01 < f["standard_error"] / true < 0.1, (name, f)     # the data pin each to a few percent
        else:
            assert f["value"] == pytest.approx(true, rel=2e-3), (name, f)
    if noise:
        assert 0.5 < s["residual_variance"] < 1.6       # 2 % noise with sigma 2 %: s^2 near 1
        assert s["phi"] < 1e-3 * s["phi_start"]
    else:
        assert s["phi"] < 1e-3 and s["phi_start"] > 1e4
    # the fitted run's stations are what residuals.csv compares, and fitted.opts runs it again
    series = read_station_series(str(out / "fitted"))
    with open(out / "residuals.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == s["observations"]
    for r in rows:
        k = ("ux", "uy", "uz").index(r["component"])
        assert float(r["simulated_m"]) == pytest.approx(series[r["name"]].at([float(r["time_s"])])[0, k],
                                                        rel=1e-12, abs=1e-15)
    if noise:
        again = tmp_path / "again"
        run_scene(str(out / "fitted.opts"), again)
        rerun = read_station_series(str(again))
        for name in series:
            assert np.allclose(rerun[name].u, series[name].u, rtol=1e-10, atol=1e-14)
        assert os.path.getsize(out / "observed_vs_simulated.png") > 10000
        with open(out / "runs.csv", newline="") as fh:
            runs = list(csv.DictReader(fh))
        assert len(runs) == s["runs"] and sum(r["purpose"] == "fitted" for r in runs) == 1
        assert sorted(os.listdir(out / "runs")) == [f"{n:04d}.log" for n in range(1, s["runs"] + 1)]
