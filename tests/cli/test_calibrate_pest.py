"""python -m pfault.calibrate --pest DIR: PEST/PEST++ files of the problem, read back with pyemu (PEST++'s
Python interface): the control file's parameters, bounds, transforms and weights, and its model command run in
DIR on the values pyemu writes through the template, whose outputs pyemu reads through the instruction file:
the values the built-in loop compares for the same parameters."""

import os
import shlex
import subprocess

import numpy as np
import pytest

from conftest import mpi_env, REPO, run
from pfault.tools.calibration import Problem
from pfault.tools.calibration_input import read_observations, read_parameters, scene_facts
from pfault.tools.runs import Run, run_pfault

SCENE = "config/twin/twin.opts"
PARAMS = ("name,option,start,lower,upper,transform,value\n"
          "E_clay,-pfault_material_clay_young_modulus,7*MPa,1*MPa,100*MPa,log,\n"
          "nu,-pfault_material_sand_poisson_ratio,0.25,-0.2,0.45,none,\n"
          'Q,-pfault_flow_well_rate,3*L/s,0.5*L/s,50*L/s,none,"0:{Q},120*day:{Q}"\n')
OBS = ("name,time,ux,uy,uz,sigma\nW0,30*day,,,-0.02,0.0004\nE1,2000000,-0.005,,-0.013,0.0003\n"
       "NE2,120*day,-0.001,-0.001,,0.0001\n")


def test_pest_files_run_the_same_model(tmp_path):
    pyemu = pytest.importorskip("pyemu")
    p, o, pest = tmp_path / "params.csv", tmp_path / "obs.csv", tmp_path / "pest"
    p.write_text(PARAMS)
    o.write_text(OBS)
    proc = run(["-m", "pfault.calibrate", SCENE, "--parameters", str(p), "--observations", str(o),
                "--pest", str(pest), "--max-iterations", "7"], timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert not os.path.exists(os.path.join(REPO, "runs", "calibrate_twin"))
    pst = pyemu.Pst(str(pest / "pfault.pst"))
    assert (pst.npar, pst.nobs, pst.control_data.noptmax) == (3, 5, 7)
    par = pst.parameter_data
    assert par.parnme.tolist() == ["e_clay", "nu", "q"] and par.partrans.tolist() == ["log", "none", "none"]
    assert np.allclose(par.parval1, [7e6, 0.25, 3e-3]) and np.allclose(par.parlbnd, [1e6, -0.2, 5e-4])
    assert np.allclose(par.parubnd, [1e8, 0.45, 5e-2]) and par.parchglim.tolist() == ["factor", "relative", "factor"]
    assert np.allclose(pst.observation_data.weight, 1 / np.array([4e-4, 3e-4, 3e-4, 1e-4, 1e-4]))
    assert np.allclose(pst.observation_data.obsval, [-0.02, -0.005, -0.013, -0.001, -0.001])
    # PEST's part: values into the template, the model command in the directory, the outputs read back
    pst.write_input_files(pst_path=str(pest))
    model = subprocess.run(shlex.split(pst.model_command[0]), cwd=pest, env=mpi_env(), capture_output=True,
                           text=True, timeout=120)
    assert model.returncode == 0, model.stderr
    simulated = pyemu.pst_utils.process_output_files(pst, pst_path=str(pest)).loc[pst.obs_names, "obsval"].values
    # the built-in loop's values for the same parameters
    params = read_parameters(str(p))
    facts = scene_facts(os.path.join(REPO, SCENE))
    obs = read_observations(str(o), facts.stations, facts.station_file, facts.time_end)
    problem = Problem(SCENE, params, obs, str(tmp_path / "runs"))
    direct = run_pfault(Run(SCENE, str(tmp_path / "direct"), problem.overrides([7e6, 0.25, 3e-3])), cwd=REPO,
                        env=mpi_env())
    assert direct.ok, direct.error
    expected = problem.simulated(direct.run.output_dir)
    assert np.all(np.abs(expected) > 1e-5)
    assert np.allclose(simulated, expected, rtol=1e-12, atol=0)
