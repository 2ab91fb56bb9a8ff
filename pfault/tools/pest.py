"""PEST / PEST++ files for a calibration (``python -m pfault.calibrate ... --pest DIR``), to run the same
problem with pestpp-glm or pestpp-ies instead of the built-in loop.

DIR holds:

- ``parameters.tpl``: template (``ptf ~``) of ``parameters.txt``: one line per parameter, its name and a
  ``~ name ~`` field (PEST pads a value with blanks to the field's width, which an option's value cannot hold:
  the model command puts the values into the options, through the ``value`` templates of the parameter file);
- ``parameters.csv``: the parameter file, its values in SI;
- ``observations.csv``: the observations in SI (time in s), one per measured component, named o00001, ...;
- ``simulated.ins``: instruction file (``pif ~``) reading ``simulated.txt``, one value a line in that order;
- ``pfault.pst``: the control file: the parameters with their bounds and transforms (PARTRANS log / none), one
  observation group ``displacement`` with weights 1/sigma, the model command line and the file pairs.

The model command is ``python -m pfault.tools.pest SCENE RUN_FROM``: in the directory PEST++ runs it in (a copy of
DIR for each agent), it runs the scene with the values of ``parameters.txt`` as overrides from RUN_FROM, the
directory the calibration was started from (where the scene's relative paths hold), its output in ``run/``, and
writes the stations interpolated to the observations' times
into ``simulated.txt`` (what pfault.calibrate compares). This module does not import PETSc.
"""

from __future__ import annotations

import csv
import os
import shlex
import sys

import numpy as np

from .calibration import Problem
from .calibration_input import COMPONENTS, Observations, Parameter, read_parameters
from .runs import Run, run_pfault

FIELD = 24                   # characters of a template field: PEST writes the value into its width
GROUP = "displacement"


def _field(name: str) -> str:
    return "~" + name.ljust(FIELD - 2) + "~"


def obs_name(i: int) -> str:
    return f"o{i + 1:05d}"


def write_pest(directory: str, scene: str, params: list[Parameter], obs: Observations,
               noptmax: int = 20) -> None:
    """The PEST files of the problem into directory (which exists)."""
    run_from = os.getcwd()
    with open(os.path.join(directory, "parameters.tpl"), "w") as fh:
        fh.write("ptf ~\n" + "".join(f"{p.name} {_field(p.name)}\n" for p in params))
    with open(os.path.join(directory, "parameters.csv"), "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["name", "option", "start", "lower", "upper", "transform", "value"])
        for p in params:
            w.writerow([p.name, "-" + p.option, repr(p.start), repr(p.lower), repr(p.upper),
                        "log" if p.log else "none", p.template])
    with open(os.path.join(directory, "observations.csv"), "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["obsnme", "name", "time_s", "component", "value_m", "sigma_m"])
        for i in range(len(obs.value)):
            w.writerow([obs_name(i), obs.station[i], repr(float(obs.time[i])), COMPONENTS[obs.component[i]],
                        repr(float(obs.value[i])), repr(float(obs.sigma[i]))])
    with open(os.path.join(directory, "simulated.ins"), "w") as fh:
        fh.write("pif ~\n" + "".join(f"l1 !{obs_name(i)}!\n" for i in range(len(obs.value))))
    command = " ".join(shlex.quote(a) for a in (sys.executable, "-m", "pfault.tools.pest", os.path.abspath(scene),
                                                run_from))
    with open(os.path.join(directory, "pfault.pst"), "w") as fh:
        fh.write(control_file(params, obs, command, noptmax))


def control_file(params: list[Parameter], obs: Observations, command: str, noptmax: int) -> str:
    """A PEST control file (the layout of the PEST manual, version 1 keywords-free form)."""
    n, m = len(params), len(obs.value)
    lines = ["pcf", "* control data", "restart estimation", f"{n} {m} 1 0 1", "1 1 double point 1 0 0",
             "10.0 -3.0 0.3 0.03 10", "10.0 10.0 0.001", "0.1", f"{noptmax} 0.01 3 3 0.01 3", "1 1 1",
             "* parameter groups",
             "pfault relative 0.01 0.0 switch 2.0 parabolic",
             "* parameter data"]
    for p in params:
        limit = "factor" if p.lower > 0 or p.upper < 0 else "relative"      # a factor limit keeps the sign
        lines.append(f"{p.name.lower()} {'log' if p.log else 'none'} {limit} {p.start!r} {p.lower!r} {p.upper!r} "
                     "pfault 1.0 0.0 1")
    lines += ["* observation groups", GROUP, "* observation data"]
    lines += [f"{obs_name(i)} {float(obs.value[i])!r} {1.0 / float(obs.sigma[i])!r} {GROUP}" for i in range(m)]
    lines += ["* model command line", command, "* model input/output", "parameters.tpl parameters.txt",
              "simulated.ins simulated.txt", ""]
    return "\n".join(lines)


def read_observation_table(path: str) -> Observations:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return Observations(np.array([r["name"] for r in rows]), np.array([float(r["time_s"]) for r in rows]),
                        np.array([COMPONENTS.index(r["component"]) for r in rows]),
                        np.array([float(r["value_m"]) for r in rows]), np.array([float(r["sigma_m"]) for r in rows]))


def forward(scene: str, run_from: str) -> int:
    """PEST's model command: the scene with the values of parameters.txt run from run_from, its output in run/,
    simulated.txt written here."""
    here = os.getcwd()
    params = read_parameters(os.path.join(here, "parameters.csv"))
    with open(os.path.join(here, "parameters.txt")) as fh:
        values = dict(line.split()[:2] for line in fh if line.strip())
    overrides = {p.option: p.option_value(float(values[p.name])) for p in params}
    result = run_pfault(Run(scene, os.path.join(here, "run"), overrides), cwd=run_from)
    if not result.ok:
        sys.stderr.write(f"{result.error}\n")
        return result.code if result.code > 0 else 1
    problem = Problem(scene, params, read_observation_table(os.path.join(here, "observations.csv")), here)
    with open(os.path.join(here, "simulated.txt"), "w") as fh:
        fh.write("".join(f"{v!r}\n" for v in problem.simulated(result.run.output_dir).tolist()))
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python -m pfault.tools.pest SCENE RUN_FROM   (the model command of pfault.pst)")
    sys.exit(forward(sys.argv[1], sys.argv[2]))
