"""Twin experiment of ``python -m pfault.calibrate`` on config/twin/twin.opts (a clay aquitard over a sand
aquifer drained by one well): observations from a run at known values of the two Young's moduli and the
pumping rate, with 2 % Gaussian noise (fixed seed); a calibration from a start a factor 2 away from each.
Used by benchmarks/calibration_twin.py and tests/verification/test_calibration.py."""

from __future__ import annotations

import csv
import os

import numpy as np

from pfault.post.rundir import read_station_series
from pfault.tools.runs import Run, run_captured, run_pfault

from . import REPO

SCENE = "config/twin/twin.opts"
TRUE = {"E_clay": 5e6, "E_sand": 40e6, "Q": 5e-3}          # Pa, Pa, m**3/s
START = {"E_clay": 10e6, "E_sand": 20e6, "Q": 10e-3}       # a factor 2 from each
BOUNDS = {"E_clay": (0.5e6, 100e6), "E_sand": (2e6, 400e6), "Q": (0.5e-3, 50e-3)}
OPTIONS = {"E_clay": "-pfault_material_clay_young_modulus", "E_sand": "-pfault_material_sand_young_modulus",
           "Q": "-pfault_flow_well_rate"}
TEMPLATES = {"Q": "0:{Q},120*day:{Q}"}
NOISE = 0.02                 # relative standard deviation of the observations
SEED = 20261125
DAY = 86400.0
RUN_TIMEOUT = 300            # s: a forward run (2 s on an idle machine) that hangs fails instead
# the measured components: settlement everywhere, the horizontal motion towards the well off its axis
COMPONENTS = {"W0": ("uz",), "N1": ("uy", "uz"), "E1": ("ux", "uz"), "NE2": ("ux", "uy", "uz"),
              "E3": ("ux", "uz")}


def write_parameters(path):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "option", "start", "lower", "upper", "transform", "value"])
        for name, option in OPTIONS.items():
            w.writerow([name, option, repr(START[name]), *map(repr, BOUNDS[name]),
                        "none" if name == "Q" else "log", TEMPLATES.get(name, "")])


def true_overrides():
    return {OPTIONS["E_clay"][1:]: repr(TRUE["E_clay"]), OPTIONS["E_sand"][1:]: repr(TRUE["E_sand"]),
            "pfault_flow_well_rate": TEMPLATES["Q"].replace("{Q}", repr(TRUE["Q"]))}


def write_observations(path, run_dir, days, noise=True):
    """Runs the scene at the true values and writes its station displacements at `days`, with noise unless
    told (sigma is 2 % of each true value either way)."""
    result = run_pfault(Run(SCENE, run_dir, true_overrides(), timeout=RUN_TIMEOUT), cwd=REPO, env=None)
    assert result.ok, result.error
    series = read_station_series(run_dir)
    rng = np.random.default_rng(SEED)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "time", "ux", "uy", "uz", "sigma"])
        for name, comps in COMPONENTS.items():
            u = series[name].at(np.asarray(days) * DAY)
            for d, row in zip(days, u):
                # one line per component (the others empty), sigma 2 % of its true value
                for c in comps:
                    k = ("ux", "uy", "uz").index(c)
                    sigma = NOISE * abs(row[k])
                    cells = ["", "", ""]
                    cells[k] = repr(row[k] + noise * sigma * rng.standard_normal())
                    w.writerow([name, f"{d}*day", *cells, repr(sigma)])


def calibrate(workdir, days, workers=2, noise=True, extra=(), timeout=900):
    """Writes the twin's files into workdir and runs the calibration there (each forward run stopped after
    RUN_TIMEOUT s, the whole after timeout s); the CompletedProcess."""
    os.makedirs(workdir, exist_ok=True)
    params, obs = os.path.join(workdir, "parameters.csv"), os.path.join(workdir, "observations.csv")
    write_parameters(params)
    write_observations(obs, os.path.join(workdir, "truth"), days, noise)
    args = ["-m", "pfault.calibrate", SCENE, "--parameters", params, "--observations", obs,
            "--workers", str(workers), "--output", os.path.join(workdir, "fit"), "--timeout", str(RUN_TIMEOUT), *extra]
    return run_captured(args, cwd=REPO, timeout=timeout)
