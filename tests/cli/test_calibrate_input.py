"""Bad input to python -m pfault.calibrate: exit 1, one line naming the file (or option) and the fix, nothing
written; a forward run that fails at the start: exit 3 with that run's own error line."""

import csv
import os

import pytest

from conftest import REPO, run

SCENE = "config/twin/twin.opts"
PARAMS = ("name,option,start,lower,upper,transform,value\n"
          "E_clay,-pfault_material_clay_young_modulus,10*MPa,1*MPa,100*MPa,log,\n"
          'Q,-pfault_flow_well_rate,10*L/s,0.5*L/s,50*L/s,none,"0:{Q},120*day:{Q}"\n')
OBS = "name,time,ux,uy,uz,sigma\nW0,30*day,,,-0.02,0.0004\nE1,60*day,-0.005,,-0.013,0.0003\n"


def calibrate(tmp_path, params=PARAMS, obs=OBS, scene=SCENE, extra=(), timeout=120):
    p, o = tmp_path / "params.csv", tmp_path / "obs.csv"
    p.write_text(params)
    o.write_text(obs)
    out = tmp_path / "fit"
    proc = run(["-m", "pfault.calibrate", str(scene), "--parameters", str(p), "--observations",
                str(o), "--output", str(out), *extra], timeout=timeout, check=False)
    return proc, out, str(p), str(o)


def error_lines(proc):
    return [line for line in proc.stderr.splitlines() if line.strip()]


CASES = {
    "not an option": (PARAMS.replace("-pfault_material_clay_young_modulus", "-pfault_clay_modulus"), OBS,
                      "parameter file {p} line 2: '-pfault_clay_modulus' is not a pfault option; give a numeric "
                      "-pfault_ option (python -m pfault -help lists them)"),
    "not numeric": (PARAMS.replace("-pfault_material_clay_young_modulus", "-pfault_box_materials"), OBS,
                    "parameter file {p} line 2: -pfault_box_materials takes names, not a real number; give a numeric "
                    "-pfault_ option (a real or a quantity), or for a table or list option a value column with "
                    "{E_clay} where the parameter goes (e.g. 0:{E_clay},10*year:{E_clay})"),
    "table without template": (PARAMS.replace('"0:{Q},120*day:{Q}"', ""), OBS,
                               "parameter file {p} line 3: -pfault_flow_well_rate takes a table, not a real number; "
                               "give "
                               "a numeric -pfault_ option (a real or a quantity), or for a table or list option a "
                               "value column with {Q} where the parameter goes (e.g. 0:{Q},10*year:{Q})"),
    "bounds reversed": (PARAMS.replace("1*MPa,100*MPa", "100*MPa,1*MPa"), OBS,
                        "parameter file {p} line 2: E_clay: lower bound 1e+08 is not below upper bound 1e+06; give "
                        "lower < upper"),
    "start outside": (PARAMS.replace("10*MPa,1*MPa", "200*MPa,1*MPa"), OBS,
                      "parameter file {p} line 2: E_clay: start 2e+08 is outside its bounds [1e+06, 1e+08]; give a "
                      "start within them"),
    "log of zero": (PARAMS.replace("0.5*L/s,50*L/s,none", "0,50*L/s,log"), OBS,
                    "parameter file {p} line 3: Q: a log transform needs a lower bound > 0, got 0; give a positive "
                    "lower bound or transform none"),
    "preconsolidation head above the initial heads": (
        PARAMS.replace("E_clay,-pfault_material_clay_young_modulus,10*MPa,1*MPa,100*MPa,log,",
                       "hp_clay,-pfault_material_clay_preconsolidation_head,-2,-10,1,,"), OBS,
        "parameter file {p} line 2: hp_clay: upper bound 1 of -pfault_material_clay_preconsolidation_head: a "
        "preconsolidation head is zero or negative (m below the initial heads); give bounds within that range"),
    "missing column": (PARAMS, OBS.replace(",sigma", ",sd"), "observation file {o}: no column sigma in its header "
                       "line 'name,time,ux,uy,uz,sd'; its first line names the columns name,time,ux,uy,uz,sigma"),
    "unknown station": (PARAMS, OBS.replace("E1,", "E9,"), "observation file {o} line 3: station 'E9' is not in "
                        "the scene's station file config/twin/stations.csv; use a station name of that file or add "
                        "the station to it"),
    "sigma zero": (PARAMS, OBS.replace("0.0003", "0"), "observation file {o} line 3: sigma 0 must be > 0 (the "
                   "standard deviation of the measurement, m)"),
    "sigma negative": (PARAMS, OBS.replace("0.0004", "-1*mm"), "observation file {o} line 2: sigma -0.001 must be > 0 "
                       "(the standard deviation of the measurement, m)"),
    "no component": (PARAMS, OBS.replace("-0.02,", ","), "observation file {o} line 2: no ux, uy or uz; give at "
                     "least one component or remove the line"),
    "bad number": (PARAMS, OBS.replace("-0.013", "-1.3cm"), "observation file {o} line 3: uz: cannot read '-1.3cm' "
                   "as a number (examples: 250, 10*year, -0.1*MPa)"),
    "too few": (PARAMS, "name,time,ux,uy,uz,sigma\nW0,30*day,,,-0.02,0.0004\n", "observation file {o}: 1 measured "
                "components for 2 parameters; give more observations than parameters"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_line_exit_1_nothing_written(tmp_path, case):
    params, obs, line = CASES[case]
    proc, out, p, o = calibrate(tmp_path, params, obs)
    assert proc.returncode == 1, proc.stderr
    assert error_lines(proc) == ["pfault.calibrate: error: " + line.replace("{p}", p).replace("{o}", o)]
    assert not os.path.exists(out) and not os.path.exists(os.path.join(REPO, "runs", "calibrate_twin"))


def test_a_scene_without_stations(tmp_path):
    scene = tmp_path / "bare.opts"
    scene.write_text("-pfault_time_end 10\n")
    proc, out, _, _ = calibrate(tmp_path, scene=scene)
    assert proc.returncode == 1
    assert error_lines(proc) == [f"pfault.calibrate: error: scene {scene}: no -pfault_stations; add the stations "
                                 "the observations name (a CSV file name,x,y,z) to the scene"]
    assert not os.path.exists(out)


def test_an_output_directory_holding_other_files_is_left_alone(tmp_path):
    out = tmp_path / "fit"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    proc, _, _, _ = calibrate(tmp_path)
    assert proc.returncode == 1
    assert error_lines(proc) == [f"pfault.calibrate: error: --output {out} holds files a calibration did not "
                                 "write; give a new or empty directory (a calibration's own output directory is "
                                 "replaced)"]
    assert os.listdir(out) == ["notes.txt"]


def test_a_start_pfault_rejects_is_its_own_error_line_exit_3(tmp_path):
    """A Poisson ratio of 0.6 is within the given bounds; pfault refuses it: the fit stops with that line."""
    params = ("name,option,start,lower,upper\nnu,-pfault_material_clay_poisson_ratio,0.6,0.1,0.7\n")
    proc, out, _, _ = calibrate(tmp_path, params=params)
    assert proc.returncode == 3, proc.stderr
    [line] = error_lines(proc)
    assert line.startswith("pfault.calibrate: error: the run at the start values failed: pfault: error: "
                           "-pfault_material_clay_poisson_ratio")
    assert line.endswith(f"(its log: {out}/runs/0001.log); every run is in {out}/runs.csv")
    with open(out / "runs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1 and (rows[0]["run"], rows[0]["purpose"], rows[0]["nu"], rows[0]["phi"]) == \
        ("1", "start", "0.6", "")
    assert rows[0]["exit_code"] == "1" and rows[0]["error"].startswith("pfault: error: ") and rows[0]["error"] in line
