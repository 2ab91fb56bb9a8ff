"""Twin experiments of ``python -m pfault.calibrate``: observations from a run at known parameter values, with
Gaussian noise (fixed seed), then a calibration from a start away from the truth. A ``Twin`` says which scene,
which parameters (their options, truth, start, bounds, transform), which station components are measured and
how noisy they are; ``calibrate`` writes the files and runs the tool.

- ``MODULI`` (config/twin/twin.opts, a clay aquitard over a sand aquifer drained by one well): the two Young's
  moduli and the pumping rate, 2 % noise, a start a factor 2 away from each;
- ``soil_twin`` (config/seasonal.opts and its one-column copy config/twin/seasonal_column.opts: seasonal head
  cycles on a declining trend over a clay that remembers): the clay's compression index Cc, recompression index
  Cr and preconsolidation head, 2 mm noise on the stations' settlement, a start a factor 2 away in the indices and
  1.5 m deeper in the head; with ``preconsolidation_head`` below the lowest head of the record, Cc is not
  identifiable (docs/verification.md).

Used by benchmarks/calibration_twin.py, benchmarks/calibration_soil_twin.py and
tests/verification/test_calibration.py, tests/verification/test_calibration_soil.py."""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field

import numpy as np

from pfault.post.rundir import read_station_series
from pfault.tools.calibration_input import scene_files_absolute
from pfault.tools.runs import Run, run_captured, run_pfault

from . import REPO

DAY = 86400.0
YEAR = 365.25 * DAY
RUN_TIMEOUT = 300            # s: a forward run (2 to 40 s on an idle machine) that hangs fails instead


@dataclass(frozen=True)
class Twin:
    """A twin experiment: the scene, the fitted parameters (name -> option, truth, start, bounds, transform,
    value template) and the observations (station -> measured components; sigma = max(noise_abs,
    noise_rel |true value|)). ``fixed``: options every run is given on top of the scene (the truth of a
    parameter not fitted), written into a scene file in the work directory."""
    scene: str
    options: dict
    true: dict
    start: dict
    bounds: dict
    components: dict
    noise_rel: float = 0.0
    noise_abs: float = 0.0
    seed: int = 20261125
    transforms: dict = field(default_factory=dict)      # name -> 'log' | 'none' ('' : the tool's default)
    templates: dict = field(default_factory=dict)       # name -> value template ({name} the parameter)
    fixed: dict = field(default_factory=dict)           # option -> value, for every run

    def sigma(self, value: np.ndarray) -> np.ndarray:
        return np.maximum(self.noise_abs, self.noise_rel * np.abs(value))

    def option_value(self, name: str, value: float) -> str:
        return self.templates.get(name, "{" + name + "}").replace("{" + name + "}", repr(float(value)))


MODULI = Twin(
    scene="config/twin/twin.opts",
    options={"E_clay": "-pfault_material_clay_young_modulus", "E_sand": "-pfault_material_sand_young_modulus",
             "Q": "-pfault_flow_well_rate"},
    true={"E_clay": 5e6, "E_sand": 40e6, "Q": 5e-3},              # Pa, Pa, m**3/s
    start={"E_clay": 10e6, "E_sand": 20e6, "Q": 10e-3},           # a factor 2 from each
    bounds={"E_clay": (0.5e6, 100e6), "E_sand": (2e6, 400e6), "Q": (0.5e-3, 50e-3)},
    # settlement everywhere, the horizontal motion towards the well off its axis
    components={"W0": ("uz",), "N1": ("uy", "uz"), "E1": ("ux", "uz"), "NE2": ("ux", "uy", "uz"), "E3": ("ux", "uz")},
    noise_rel=0.02, seed=20261125,
    transforms={"E_clay": "log", "E_sand": "log", "Q": "none"},
    templates={"Q": "0:{Q},120*day:{Q}"})

# the names the moduli twin has always had
SCENE, TRUE, START, BOUNDS, OPTIONS = MODULI.scene, MODULI.true, MODULI.start, MODULI.bounds, MODULI.options
TEMPLATES, NOISE, SEED, COMPONENTS = MODULI.templates, MODULI.noise_rel, MODULI.seed, MODULI.components

SOIL_NOISE = 0.002           # m: the standard deviation of a levelling or GNSS settlement
SOIL_PARAMETERS = {"Cc_clay": "-pfault_material_clay_compression_index",
                   "Cr_clay": "-pfault_material_clay_recompression_index",
                   "hp_clay": "-pfault_material_clay_preconsolidation_head"}


def soil_twin(scene: str = "config/seasonal.opts", preconsolidation_head: float = -2.0,
              names: tuple = tuple(SOIL_PARAMETERS), start: dict | None = None) -> Twin:
    """The seasonal scene's clay (Cc 0.30, Cr 0.04 as in the scene; its preconsolidation head, -2 m as in the
    scene unless given) fitted from Cc 0.15, Cr 0.08 and a head 1.5 m deeper (unless ``start`` says otherwise),
    to the two benchmarks' settlement with 2 mm noise; ``names``: the parameters fitted, the others held at their
    truth."""
    true = {"Cc_clay": 0.30, "Cr_clay": 0.04, "hp_clay": preconsolidation_head}
    start = {"Cc_clay": 0.15, "Cr_clay": 0.08, "hp_clay": preconsolidation_head - 1.5, **(start or {})}
    bounds = {"Cc_clay": (0.03, 3.0), "Cr_clay": (0.004, 0.4), "hp_clay": (-15.0, 0.0)}
    return Twin(scene=scene, options={n: SOIL_PARAMETERS[n] for n in names}, true={n: true[n] for n in names},
                start={n: start[n] for n in names}, bounds={n: bounds[n] for n in names},
                components={"BM_CENTRE": ("uz",), "BM_EDGE": ("uz",)}, noise_abs=SOIL_NOISE, seed=20261128,
                fixed={SOIL_PARAMETERS[n][1:]: repr(true[n]) for n in SOIL_PARAMETERS if n not in names})


def write_parameters(path, twin: Twin = MODULI):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "option", "start", "lower", "upper", "transform", "value"])
        for name, option in twin.options.items():
            w.writerow([name, option, repr(twin.start[name]), *map(repr, twin.bounds[name]),
                        twin.transforms.get(name, ""), twin.templates.get(name, "")])


def true_overrides(twin: Twin = MODULI):
    return {option[1:]: twin.option_value(name, twin.true[name]) for name, option in twin.options.items()}


def scene_of(workdir, twin: Twin = MODULI) -> str:
    """The scene the calibration runs: the twin's own, or with its fixed options a file in workdir that includes
    it, names its data files by absolute paths (as fitted.opts does: they are found beside the scene) and adds
    them."""
    if not twin.fixed:
        return twin.scene
    path = os.path.join(os.path.abspath(workdir), "scene.opts")
    scene = os.path.join(REPO, twin.scene)
    with open(path, "w") as fh:
        fh.write(f"-options_file {scene}\n")
        fh.writelines(f"-{k} {v}\n" for k, v in {**scene_files_absolute(scene), **twin.fixed}.items())
    return path


def write_observations(path, run_dir, days, noise=True, twin: Twin = MODULI, scene=None):
    """Runs the scene at the true values and writes its station displacements at `days`, with noise unless
    told (sigma, twin.sigma of each true value, either way)."""
    result = run_pfault(Run(scene or twin.scene, run_dir, true_overrides(twin), timeout=RUN_TIMEOUT), cwd=REPO)
    assert result.ok, result.error
    series = read_station_series(run_dir)
    rng = np.random.default_rng(twin.seed)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "time", "ux", "uy", "uz", "sigma"])
        for name, comps in twin.components.items():
            u = series[name].at(np.asarray(days) * DAY)
            for d, row in zip(days, u):
                # one line per component (the others empty)
                for c in comps:
                    k = ("ux", "uy", "uz").index(c)
                    sigma = float(twin.sigma(row[k]))
                    cells = ["", "", ""]
                    cells[k] = repr(row[k] + noise * sigma * rng.standard_normal())
                    w.writerow([name, f"{d}*day", *cells, repr(sigma)])


def calibrate(workdir, days, workers=2, noise=True, extra=(), timeout=900, twin: Twin = MODULI):
    """Writes the twin's files into workdir and runs the calibration there (each forward run stopped after
    RUN_TIMEOUT s, the whole after timeout s); the CompletedProcess."""
    os.makedirs(workdir, exist_ok=True)
    params, obs = os.path.join(workdir, "parameters.csv"), os.path.join(workdir, "observations.csv")
    scene = scene_of(workdir, twin)
    write_parameters(params, twin)
    write_observations(obs, os.path.join(workdir, "truth"), days, noise, twin, scene)
    args = ["-m", "pfault.calibrate", scene, "--parameters", params, "--observations", obs,
            "--workers", str(workers), "--output", os.path.join(workdir, "fit"), "--timeout", str(RUN_TIMEOUT), *extra]
    return run_captured(args, cwd=REPO, timeout=timeout)


def step_days(time_end_years: float, steps: int) -> list[float]:
    """The days of a scene's time steps (every step's end), as observation times."""
    return [round(k * time_end_years * YEAR / steps / DAY, 6) for k in range(1, steps + 1)]
