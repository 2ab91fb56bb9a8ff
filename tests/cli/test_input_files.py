"""The data files a run reads are recorded (input_files.json, checkpoint.h5) and a restart checks them.

The oedometer column (10 m x 10 m x 100 m, 4 cells high) under a MODFLOW model of one layer whose heads fall by 5 m
over 10 days, its modulus from a field file (10 MPa at every depth), one station: a run of 2 steps to 5 days on 2
ranks (its checkpoint written by every rank), then restarts to 10 days in 4 steps. The settlement is c_M rho_w g Dh
H, linear in time: steps 1-4 at 1/4, 1/2, 3/4 and 1 of it.

- The record holds every data file with its absolute path, size and SHA-256 (hashlib of the file's bytes).
- The head file rewritten in place (a 10 m fall), then the field file too (a comment line: the same values): the
  restart stops on 2 ranks with one line naming the files, the options and the fix, exit code 1, the run directory
  untouched.
- -pfault_restart_changed_inputs naming an option that names no data file, or without -pfault_restart: one line.
- With -pfault_restart_changed_inputs naming both, the restart runs: steps 1-2 those of the old heads, 3-4 those of
  the new (2 c_M rho_w g 5 m H x 3/4 and x 1), and summary.json lists each file then and now.
- A checkpoint without the record (an earlier pfault's): continued with one warning, summary.json's
  restart.inputs_checked false.
"""

import hashlib
import json
import os
import shutil

import h5py
import numpy as np

from conftest import OEDOMETER
from pfault.tools.mf6_write import write_dis_grb, write_heads
from test_bad_input import _error_lines, run_pfault

E, NU, RHO_G, H = 10e6, 0.25, 1000.0 * 9.80665, 100.0
C_M = (1 + NU) * (1 - 2 * NU) / (E * (1 - NU))


def write_heads_file(path, drop):
    write_heads(str(path), [0.0, 10.0], np.array([0.0, -drop])[:, None, None, None] * np.ones((2, 1, 1, 2)))


def column(tmp):
    """The scene file and its data files: {option: path}."""
    files = {"pfault_heads_file": tmp / "col.hds", "pfault_heads_grid": tmp / "col.dis.grb",
             "pfault_material_soil_young_modulus": tmp / "modulus.csv", "pfault_stations": tmp / "stations.csv"}
    write_dis_grb(str(files["pfault_heads_grid"]), [5.0, 5.0], [10.0], np.zeros((1, 2)), np.full((1, 1, 2), -100.0))
    write_heads_file(files["pfault_heads_file"], 5.0)
    files["pfault_material_soil_young_modulus"].write_text("z,young_modulus [MPa]\n-100,10\n0,10\n")
    files["pfault_stations"].write_text("name,x,y,z\ntop,5,5,0\n")
    lines = [ln for ln in open(OEDOMETER).read().splitlines()
             if not ln.startswith(("-pfault_material_soil_pressure_change", "-pfault_time_", "-pfault_box_cells",
                                   "-pfault_material_soil_young_modulus"))]
    modulus = files["pfault_material_soil_young_modulus"]
    lines += ["-pfault_box_cells 1,1,4", f"-pfault_material_soil_young_modulus field:{modulus}",
              f"-pfault_heads_file {files['pfault_heads_file']}", f"-pfault_heads_grid {files['pfault_heads_grid']}",
              f"-pfault_stations {files['pfault_stations']}", "-pfault_figures false"]
    scene = tmp / "column.opts"
    scene.write_text("\n".join(lines) + "\n")
    return scene, files


def record_of(files):
    return [{"option": option, "path": str(path), "size_bytes": os.path.getsize(path),
             "sha256": hashlib.sha256(path.read_bytes()).hexdigest()} for option, path in files.items()]


def snapshot(directory):
    return {f: os.stat(directory / f).st_mtime_ns for f in os.listdir(directory)}


def pfault(scene, ranks, *extra):
    code, stdout, stderr = run_pfault(["-m", "pfault", str(scene), *extra], ranks)
    return code, stdout, stderr


def test_restart_checks_the_data_files_it_reads(tmp_path):
    scene, files = column(tmp_path)
    part = tmp_path / "part"
    code, _, stderr = pfault(scene, 2, "-pfault_output_dir", str(part), "-pfault_time_end", "5*day",
                             "-pfault_time_steps", "2")
    assert code == 0, stderr[-3000:]
    then = record_of(files)
    assert json.loads((part / "input_files.json").read_text()) == then
    with h5py.File(part / "checkpoint.h5", "r") as h5:
        assert json.loads(bytes(h5["input_files"][()]).decode()) == then

    # the heads rewritten in place: one line on 2 ranks, nothing written
    write_heads_file(files["pfault_heads_file"], 10.0)
    new_heads = record_of(files)[0]
    before = snapshot(part)
    restart = ("-pfault_restart", str(part), "-pfault_time_end", "10*day", "-pfault_time_steps", "4")
    code, stdout, stderr = pfault(scene, 2, *restart)
    assert code == 1 and _error_lines(stderr) == [
        f"pfault: error: -pfault_restart {part}: -pfault_heads_file {files['pfault_heads_file']} has changed since "
        f"that run read it (now {new_heads['size_bytes']:,} bytes, SHA-256 {new_heads['sha256'][:12]}...; then "
        f"{then[0]['size_bytes']:,} bytes, {then[0]['sha256'][:12]}...); the checkpoint is the answer to the files "
        "that run read: give those files to continue it as it was, or -pfault_restart_changed_inputs "
        "pfault_heads_file to continue with the files as they are now (the steps up to the checkpoint stay those of "
        "the old files)"], stderr[-3000:]
    assert "Traceback" not in stderr and "continuing" not in stdout

    # the field file too (a comment: the same values, another file): both named, in one line
    with open(files["pfault_material_soil_young_modulus"], "a") as fh:
        fh.write("# checked\n")
    code, _, stderr = pfault(scene, 1, *restart)
    lines = _error_lines(stderr)
    assert code == 1 and len(lines) == 1, stderr[-3000:]
    assert "(and -pfault_material_soil_young_modulus)" in lines[0] and \
        "-pfault_restart_changed_inputs pfault_heads_file,pfault_material_soil_young_modulus to continue" in lines[0]
    # an option that names no data file
    code, _, stderr = pfault(scene, 1, *restart, "-pfault_restart_changed_inputs", "pfault_heads_grod")
    assert code == 1 and _error_lines(stderr) == [
        "pfault: error: -pfault_restart_changed_inputs pfault_heads_grod: -pfault_heads_grod names no data file of "
        f"this run or of the run in -pfault_restart {part}; the options that name this run's data files: "
        "pfault_heads_file, pfault_heads_grid, pfault_material_soil_young_modulus, pfault_stations"]
    assert snapshot(part) == before

    # continued with the changed files, as the user says: steps 3-4 from the new heads
    cont = tmp_path / "cont"
    accept = ("-pfault_restart_changed_inputs", "pfault_heads_file,-pfault_material_soil_young_modulus")
    code, stdout, stderr = pfault(scene, 1, *restart, *accept, "-pfault_output_dir", str(cont))
    assert code == 0, stderr[-3000:]
    s = json.loads((cont / "summary.json").read_text())
    exact = C_M * RHO_G * 5.0 * H
    assert np.allclose([r["max_subsidence_m"] for r in s["steps"]],
                       [exact / 4, exact / 2, 2 * exact * 3 / 4, 2 * exact], rtol=1e-8)
    now = record_of(files)
    assert s["restart"]["inputs_checked"] is True
    assert s["restart"]["changed_inputs"] == [
        {"option": e["option"], "then": {k: e[k] for k in ("path", "size_bytes", "sha256")},
         "now": {k: n[k] for k in ("path", "size_bytes", "sha256")}} for e, n in zip(then[::2], now[::2])]
    assert json.loads((cont / "input_files.json").read_text()) == now
    assert stderr.count("pfault: warning: -pfault_restart") == 1 and "continuing with changed data files" in stderr

    # a checkpoint without the record: continued, with a warning that the files could not be checked
    old = tmp_path / "old"
    shutil.copytree(part, old)
    with h5py.File(old / "checkpoint.h5", "r+") as h5:
        del h5["input_files"]
    code, _, stderr = pfault(scene, 1, *restart[:1], str(old), *restart[2:])
    assert code == 0, stderr[-3000:]
    warnings = [ln for ln in stderr.splitlines() if ln.startswith("pfault: warning:")]
    assert warnings == [f"pfault: warning: -pfault_restart {old}: its checkpoint.h5 holds no record of the data files "
                        "that run read (written by an earlier pfault), so they could not be checked: the continued "
                        "steps read the files as they are now, which must be those of that run for it to continue as "
                        "it was"], stderr[-3000:]
    s = json.loads((old / "summary.json").read_text())
    assert s["restart"] == {"from": str(old), "step": 2, "inputs_checked": False, "changed_inputs": []}
    assert s["completed_steps"] == [1, 2, 3, 4]


def test_changed_inputs_need_a_restart_and_a_data_file(tmp_path):
    scene, _ = column(tmp_path)
    code, _, stderr = pfault(scene, 1, "-pfault_restart_changed_inputs", "pfault_heads_file", "-pfault_output_dir",
                             str(tmp_path / "out"))
    assert code == 1 and _error_lines(stderr) == [
        "pfault: error: -pfault_restart_changed_inputs: only with -pfault_restart DIR (it names the data files that "
        "may differ from those of the run DIR continues); remove it"]
    assert not (tmp_path / "out").exists()
