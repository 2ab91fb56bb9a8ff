"""Twin experiment of python -m pfault.calibrate on soils that remember (studies/calibration_twin.py's soil_twin on
config/twin/seasonal_column.opts: seasonal head cycles on a declining trend, one column of cells, 16 half-year
steps): the clay's compression index Cc, recompression index Cr and preconsolidation head fitted to the two
benchmarks' settlement with 2 mm Gaussian noise (fixed seed), from a start off the truth, each within two standard
errors of it. With the preconsolidation head below every head of the record (-8 m; the clay's lowest is -7.125 m)
no settlement depends on Cc: the tool reports it not identifiable (no value, an infinite standard error) and
still fits Cr. benchmarks/calibration_soil_twin.py runs the full-size scene."""

import csv
import json
import os

import numpy as np
import pytest

from studies import calibration_twin as twin

SCENE = "config/twin/seasonal_column.opts"
DAYS = twin.step_days(8, 16)             # the column's steps: the summer lows and winter highs of 8 years


def summary(out):
    with open(os.path.join(out, "calibration.json")) as fh:
        return json.load(fh)


def parameters_csv(out):
    with open(os.path.join(out, "parameters.csv"), newline="") as fh:
        return {r["name"]: r for r in csv.DictReader(fh)}


def within_two_se(f, true):
    if "standard_error_log10" in f:
        return abs(np.log10(f["value"] / true)) < 2 * f["standard_error_log10"]
    return abs(f["value"] - true) < 2 * f["standard_error"]


def test_cc_cr_and_the_preconsolidation_head_are_recovered_within_two_standard_errors(tmp_path):
    t = twin.soil_twin(SCENE, start={"Cc_clay": 0.27, "Cr_clay": 0.045, "hp_clay": -2.3})
    proc = twin.calibrate(str(tmp_path), DAYS, workers=2, twin=t)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    s = summary(tmp_path / "fit")
    assert s["converged"] and s["failed_runs"] == 0 and s["not_identifiable"] == [] and s["runs"] <= 20
    assert s["observations"] == 2 * len(DAYS) == 32 and s["degrees_of_freedom"] == 29
    assert 0.5 < s["residual_variance"] < 1.5                 # 2 mm noise with sigma 2 mm: s^2 near 1
    assert s["phi_start"] > 500 * s["phi"]                       # 2.27e4 -> 24.1
    for name, true in t.true.items():
        f = s["fitted"][name]
        assert f["identifiable"] and within_two_se(f, true), (name, f)
    # the trend pins Cc to a fraction of a percent, the seasonal rebounds Cr to a few percent, the onset of the
    # virgin compaction the preconsolidation head to a centimetre
    fitted = s["fitted"]
    assert 5e-4 < fitted["Cc_clay"]["standard_error_log10"] < 3e-3
    assert 5e-3 < fitted["Cr_clay"]["standard_error_log10"] < 3e-2
    assert 3e-3 < fitted["hp_clay"]["standard_error"] < 3e-2
    assert "standard_error_log10" not in fitted["hp_clay"]           # the head is fitted as it is, the indices as log10
    assert all(r["identifiable"] == "true" for r in parameters_csv(tmp_path / "fit").values())


def test_cc_is_reported_not_identifiable_when_the_heads_never_reach_the_preconsolidation_head(tmp_path):
    t = twin.soil_twin(SCENE, preconsolidation_head=-8.0, names=("Cc_clay", "Cr_clay"),
                       start={"Cc_clay": 0.2, "Cr_clay": 0.045})
    proc = twin.calibrate(str(tmp_path), DAYS, workers=2, twin=t)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Cc_clay      NOT IDENTIFIABLE" in proc.stdout
    assert "Cc_clay not identifiable from these observations" in proc.stdout
    s = summary(tmp_path / "fit")
    cc, cr = s["fitted"]["Cc_clay"], s["fitted"]["Cr_clay"]
    assert s["not_identifiable"] == ["Cc_clay"] and s["converged"] and s["runs"] <= 16
    assert cc["identifiable"] is False and cc["value"] is None and cc["standard_error"] is None
    assert cc["held_at"] == pytest.approx(0.2)                       # never moved: no residual depends on it
    assert cr["identifiable"] and within_two_se(cr, 0.04) and cr["standard_error_log10"] < 5e-3, cr
    rows = parameters_csv(tmp_path / "fit")
    assert rows["Cc_clay"]["identifiable"] == "false" and rows["Cc_clay"]["fitted"] == ""
    assert rows["Cc_clay"]["standard_error"] == "inf" and rows["Cc_clay"]["lower_2se"] == ""
    assert float(rows["Cr_clay"]["fitted"]) == pytest.approx(cr["value"], rel=1e-12)
    with open(tmp_path / "fit" / "fitted.opts") as fh:
        assert "# Cc_clay is not identifiable from the observations: held at its value of the fit\n" in fh.read()
