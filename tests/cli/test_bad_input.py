"""Catalogue of bad inputs and faults, at 1 and 2 ranks.

Each case asserts the exit code, the one line that names the problem (printed once, without a traceback
unless it is a bug), that every rank ends (a run that has not ended within its timeout fails its test: on 2 ranks
the MPI workers answer only when every rank has ended the run, or the job aborted) and what is on disk
afterwards: no output directory, or the content a previous run left there untouched.
"""

import json
import os
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest
from petsc4py import PETSc

from conftest import FLOW_BOX, OEDOMETER, REPO, TWO_BLOCKS, run

OED = OEDOMETER
OED_FILE = os.path.join(REPO, OEDOMETER)      # included from files in tmp (an include is relative to its file)
TIMEOUT = 60
FREE_SIDES = ["-pfault_bc_xmin_type", "free", "-pfault_bc_xmax_type", "free", "-pfault_bc_ymin_type", "free",
              "-pfault_bc_ymax_type", "free"]


def run_pfault(args, ranks, timeout=TIMEOUT):
    """``python ARGS`` on ``ranks`` ranks (conftest.run: pfault's command line in this process or the MPI
    workers, anything else a process); (exit code, stdout, stderr). A run past ``timeout`` s fails the test."""
    proc = run(args, ranks=ranks, timeout=timeout, check=False)
    return proc.returncode, proc.stdout, proc.stderr


def write(path, text):
    path.write_text(text)
    return str(path)


@dataclass
class Case:
    id: str
    args: Callable          # (tmp_path, out, ranks) -> arguments after the interpreter
    code: int
    message: str
    disk: str = "none"      # none: no output dir | kept: a previous run's files untouched | file: a file
                            # in the way untouched | partial: a run that stopped in step 3, its summary.json
                            # and checkpoint.h5 those of step 2, the error and the code in summary.json
                            # (also when one rank failed alone and aborted the job: that rank wrote them)


def scene(*extra):
    return lambda tmp, out, ranks: ["-m", "pfault", OED, "-pfault_output_dir", str(out), *extra]


def scene_file(text, *extra):
    return lambda tmp, out, ranks: ["-m", "pfault", write(tmp / "scene.opts", text), "-pfault_output_dir",
                                    str(out), *extra]


def stations(text):
    """The oedometer with the station file ``text``."""
    return lambda tmp, out, ranks: ["-m", "pfault", OED, "-pfault_output_dir", str(out), "-pfault_stations",
                                    write(tmp / "stations.csv", text)]


def inject(kind, rank, step):
    """A fault on one rank (rank 0 when there is only one), in time step ``step``."""
    return lambda tmp, out, ranks: ["tests/scripts/inject_fault.py", kind, str(min(rank, ranks - 1)), str(step),
                                    OED, "-pfault_output_dir", str(out)]


def field_scene(prop, text, suffix=""):
    """The oedometer with -pfault_material_soil_<prop> naming the field in ``text`` (a CSV file)."""
    def args(tmp, out, ranks):
        return ["-m", "pfault", OED, "-pfault_output_dir", str(out), f"-pfault_material_soil_{prop}",
                f"field:{write(tmp / 'field.csv', text)}{suffix}"]
    return args


def include_loop(tmp, out, ranks):
    """a.opts includes b.opts, which includes a.opts again."""
    write(tmp / "b.opts", f"-options_file {OED_FILE}\n-options_file {tmp / 'a.opts'}\n")
    return ["-m", "pfault", write(tmp / "a.opts", f"-options_file {tmp / 'b.opts'}\n"), "-pfault_output_dir", str(out)]


def petsc_index_bytes():
    """Size of PETSc's indices."""
    return np.dtype(PETSc.IntType).itemsize


BINARY = "\x7fELF\x02\x01\x01\x00\x00\x00" + "\x00" * 40

CASES = [
    # usage: exit 2
    Case("no_scene", lambda tmp, out, ranks: ["-m", "pfault"], 2, "pfault: error: no scene file given"),
    Case("missing_scene", lambda tmp, out, ranks: ["-m", "pfault", "config/no_such.opts"], 2,
         "scene file 'config/no_such.opts' not found"),
    Case("scene_is_a_directory", lambda tmp, out, ranks: ["-m", "pfault", "config"], 2,
         "scene file 'config' is not a file"),
    Case("second_scene_file", scene("config/demo.opts"), 2,
         "a second scene file 'config/demo.opts' after config/oedometer.opts"),
    Case("stray_argument", scene("-pfault_time_steps", "2", "3"), 2,
         "unexpected argument '3' after '-pfault_time_steps 2'"),
    Case("scene_after_options", lambda tmp, out, ranks: ["-m", "pfault", "-pfault_time_steps", "2", OED], 2,
         "the scene file 'config/oedometer.opts' must come first"),
    # scene files: exit 1
    Case("binary_scene", scene_file(BINARY), 1, "scene.opts: not a text options file (binary content)"),
    Case("line_without_option", scene_file(f"-options_file {OED_FILE}\nfoo bar\n"), 1,
         "scene.opts line 2: 'foo' is not an option name"),
    Case("two_options_on_a_line", scene_file(f"-options_file {OED_FILE}\n-pfault_time_steps 2 -pfault_time_end 3\n"),
         1, "scene.opts line 2: two options on one line (-pfault_time_steps ... -pfault_time_end)"),
    Case("two_values", scene_file(f"-options_file {OED_FILE}\n-pfault_box_size 10, 10, 100\n"), 1,
         "line 2: -pfault_box_size has more than one value ('10, 10, 100')"),
    Case("missing_nested_file", scene_file(f"-options_file {OED_FILE}\n-options_file config/solver/none.opts\n"), 1,
         "line 2: -options_file config/solver/none.opts: no such file"),
    Case("include_loop", include_loop, 1, "is already being read (the files include each other)"),
    Case("malformed_solver_file", lambda tmp, out, ranks: ["-m", "pfault", OED, "-pfault_output_dir", str(out),
                                                            "-pfault_solver", write(tmp / "solver.opts",
                                                                                    "-ksp_type cg -pc_type gamg\n")],
         1, "solver.opts line 1: two options on one line (-ksp_type ... -pc_type)"),
    Case("missing_options_file_on_command_line", scene("-options_file", "none.opts"), 1,
         "on the command line: -options_file none.opts: no such file"),
    # option values: exit 1
    Case("length_given_as_pressure", scene("-pfault_box_size", "10,10,100*MPa"), 1,
         "-pfault_box_size: '100*MPa' is a pressure, but this option takes a length in m"),
    Case("time_given_as_length", scene("-pfault_time_end", "10*m"), 1,
         "-pfault_time_end: '10*m' is a length, but this option takes a time in s"),
    Case("unit_on_a_plain_number", scene("-pfault_material_soil_poisson_ratio", "0.25*MPa"), 1,
         "-pfault_material_soil_poisson_ratio: '0.25*MPa' is a pressure, but this option takes a plain number"),
    Case("table_value_of_wrong_dimension", scene("-pfault_material_soil_pressure_change", "0:0,10:-1*m"), 1,
         "-pfault_material_soil_pressure_change: '-1*m' is a length, but this option takes a pressure in Pa"),
    Case("table_time_of_wrong_dimension", scene("-pfault_material_soil_pressure_change", "0:0,1*MPa:-1*MPa"), 1,
         "-pfault_material_soil_pressure_change: '1*MPa' is a pressure, but this option takes a time in s"),
    Case("infinite_end_time", scene("-pfault_time_end", "1e999"), 1, "-pfault_time_end: '1e999' is not a finite"),
    Case("overflow_through_unit", scene("-pfault_material_soil_young_modulus", "1e300*GPa"), 1,
         "-pfault_material_soil_young_modulus: '1e300*GPa' is not a finite number"),
    Case("not_a_number", scene("-pfault_time_end", "soon"), 1, "-pfault_time_end: cannot read 'soon' as a number"),
    Case("unknown_unit", scene("-pfault_time_end", "10*years"), 1, "-pfault_time_end: unknown unit 'years'"),
    Case("negative_k0", scene("-pfault_geostatic", "true", "-pfault_geostatic_k0", "-0.5"), 1,
         "-pfault_geostatic_k0: must not be negative, got -0.5"),
    Case("k0_old_unset_value", scene("-pfault_geostatic", "true", "-pfault_geostatic_k0", "-1"), 1,
         "-pfault_geostatic_k0: must not be negative, got -1"),
    Case("output_every_zero", scene("-pfault_output_every", "0"), 1, "-pfault_output_every: must be at least 1"),
    Case("fractional_cells", scene("-pfault_box_cells", "1.5,1,2"), 1,
         "-pfault_box_cells: '1.5' is not a whole number"),
    Case("zero_cells", scene("-pfault_box_cells", "1,1,0"), 1,
         "-pfault_box_cells: need at least one cell per direction"),
    Case("negative_box_size", scene("-pfault_box_size", "10,10,-100"), 1, "-pfault_box_size: lengths must be "
         "positive, got 10,10,-100"),
    Case("zero_time_steps", scene("-pfault_time_steps", "0"), 1, "-pfault_time_steps: need at least one step"),
    Case("misspelled_option", scene("-pfault_bc_top_typ", "free"), 1, "did you mean -pfault_bc_top_type?"),
    Case("bad_choice", scene("-pfault_bc_top_type", "clamped"), 1, "-pfault_bc_top_type: 'clamped' is not one of"),
    Case("missing_mesh_file", scene("-pfault_mesh_file", "nowhere.msh"), 1,
         "-pfault_mesh_file nowhere.msh: no such file; give a gmsh MSH 4.1 file"),
    # material properties from spatial fields (pfault.materials.properties): checked before anything is written
    Case("field_with_nans", field_scene("young_modulus", "z,E [MPa]\n-100,10\n-50,nan\n0,10\n"), 1,
         "field.csv: 1 of 3 E are NaN or infinite (line 3); fill them (or remove those points) and run again"),
    Case("field_negative_modulus", field_scene("young_modulus", "z,E [MPa]\n-100,10\n0,-10\n"), 1,
         "field.csv: 1 values are not positive (e.g. -1e+07); fix the file's values"),
    Case("field_poisson_ratio_one_half", field_scene("poisson_ratio", "z,nu\n-100,0.3\n0,0.5\n"), 1,
         "field.csv: 1 values are not in (-1, 0.5) (e.g. 0.5)"),
    Case("field_not_covering_the_cells", field_scene("young_modulus", "z,E [MPa]\n-60,10\n0,20\n"), 1,
         "field.csv: 24 of 60 cells of 'soil' lie outside the field (their centroids at z -97.5..-62.5 m; the field "
         "spans z -60..0 m); "
         "extend the file or add ,outside=nearest to the option"),
    Case("field_in_a_wrong_unit", field_scene("young_modulus", "z,E [m]\n-100,10\n0,20\n"), 1,
         "field.csv: 'E' is in m, a length, but the option takes a pressure in Pa; give the variable in that unit"),
    Case("field_variable_not_in_file", field_scene("young_modulus", "z,E\n-100,1e7\n0,2e7\n", ",variable=Ec"), 1,
         "field.csv: no variable 'Ec' (the file has E); give one of them as variable=NAME"),
    Case("field_file_missing", scene("-pfault_material_soil_density", "field:maps/none.nc"), 1,
         "-pfault_material_soil_density field:maps/none.nc: no such file; give the path of a CSV, HDF5 or NetCDF "
         "file"),
    Case("misspelled_ground_surface", scene("-pfault_ground_surface", "tpo"), 1,
         "-pfault_ground_surface tpo: no such physical surface in the mesh; give one of bottom, top, xmax", "kept"),
    Case("unused_solver_option", scene("-ksp_rtoll", "1e-3"), 1, "unused option -ksp_rtoll", "kept"),
    Case("box_beyond_petsc_indices", scene("-pfault_box_cells", "3000,3000,3000"), 1,
         "-pfault_box_cells 3000,3000,3000: 8.11e+10 displacement unknowns exceed the 32-bit indices"),
    # observations (pfault.io.stations, pfault.io.insar): exit 1, found before the first solve
    Case("station_outside_the_mesh", stations("name,x,y,z\ntop,5,5,0\nfar,50,5,-10\n"), 1,
         "1 station(s) outside the mesh: 'far' at (50, 5, -10); the mesh spans x 0..10, y 0..10, z -100..0 m (site "
         "coordinates): move them inside or remove them"),
    Case("station_file_without_columns", stations("name,x,y\ntop,5,5\n"), 1,
         "no column z in its header line 'name,x,y'; its first line names the columns: name,x,y,z (and optionally "
         "side)"),
    Case("station_file_missing", scene("-pfault_stations", "no_such_stations.csv"), 1,
         "-pfault_stations no_such_stations.csv: no such file; give a CSV file whose first line names the columns"),
    Case("los_not_a_unit_vector", scene("-pfault_insar_los", "1,0,1"), 1,
         "-pfault_insar_los 1,0,1: not a unit vector (length 1.414; rounded direction cosines are within 0.01 of 1 "
         "and pfault normalises them); give the east, north, up components of the unit vector from the ground to the "
         "satellite"),
    Case("insar_raster_beyond_memory", scene("-pfault_box_size", "2000,2000,100", "-pfault_insar_los", "0,0,1",
                                             "-pfault_insar_spacing", "1*mm"), 5,
         "-pfault_insar_spacing 0.001 m: the raster over the land surface (2000 x 2000 m) would have 4e+12 pixels "
         "(2e+06 x 2e+06) and need about "),
    Case("insar_spacing_not_positive", scene("-pfault_insar_los", "0,0,1", "-pfault_insar_spacing", "0"), 1,
         "-pfault_insar_spacing 0: the pixel size must be positive (m)"),
    # boundary conditions that do not hold the body: exit 1, found from the constraints before any solve
    Case("floating_body", scene(*FREE_SIDES, "-pfault_bc_bottom_type", "free"), 1,
         "leave the body free to translate along x, y and z and to rotate about x, y and z (nothing holds it); "
         "fix or roll a surface, e.g. -pfault_bc_bottom_type fixed", "kept"),
    Case("roller_bottom_only", scene(*FREE_SIDES, "-pfault_bc_bottom_type", "roller"), 1,
         "free to translate along x and y and to rotate about z"),
    Case("no_vertical_support", scene("-pfault_bc_bottom_type", "free"), 1, "free to translate along z (nothing"),
    Case("fault_scene_pulled_loose", lambda tmp, out, ranks: [
        "-m", "pfault", TWO_BLOCKS, "-pfault_output_dir", str(out), "-pfault_bc_xmin_type",
        "traction"], 1, "free to translate along x and to rotate about y"),
    Case("fault_on_the_outer_boundary_with_bcs", scene("-pfault_faults", "xmax"), 1,
         "-pfault_faults: 'xmax' is a fault and has boundary conditions (-pfault_bc_xmax_type); a fault must be an "
         "interior surface of the mesh, boundary conditions act on its outer boundary: remove 'xmax' from "
         "-pfault_faults or remove its -pfault_bc_xmax_* options"),
    Case("negative_tensile_strength", lambda tmp, out, ranks: [
        "-m", "pfault", TWO_BLOCKS, "-pfault_output_dir", str(out), "-pfault_fault_fault_tensile_strength",
        "-50*kPa"], 1, "-pfault_fault_fault_tensile_strength: must not be negative (0: a pre-existing fault)"),
    Case("residual_cohesion_above_cohesion", lambda tmp, out, ranks: [
        "-m", "pfault", TWO_BLOCKS, "-pfault_output_dir", str(out), "-pfault_fault_fault_tensile_strength",
        "50*kPa", "-pfault_fault_fault_cohesion", "20*kPa", "-pfault_fault_fault_residual_cohesion", "30*kPa"], 1,
        "-pfault_fault_fault_residual_cohesion: must lie in [0, the cohesion 20000 Pa]"),
    Case("unchanged_pore_pressure_of_no_material", scene("-pfault_pore_pressure_unchanged_materials", "clay"), 1,
         "-pfault_pore_pressure_unchanged_materials: 'clay' is not a material of the mesh (materials: soil)"),
    Case("unchanged_pore_pressure_of_a_material_with_a_table",
         scene("-pfault_pore_pressure_unchanged_materials", "soil"), 1,
         "-pfault_pore_pressure_unchanged_materials: soil has a head_drawdown or pressure_change table of its own"),
    Case("unchanged_pore_pressure_in_a_scene_without_one", lambda tmp, out, ranks: [
        "-m", "pfault", TWO_BLOCKS, "-pfault_output_dir", str(out), "-pfault_pore_pressure_unchanged_materials",
        "rock"], 1, "-pfault_pore_pressure_unchanged_materials: the scene changes no pore pressure"),
    Case("geostatic_stress_without_a_geostatic_start", scene("-pfault_geostatic_stress", "lithostatic"), 1,
         "-pfault_geostatic_stress: sets the initial stress of a geostatic start; add -pfault_geostatic true"),
    # output: exit 4 (1 for an empty name), found before the first solve
    Case("output_in_proc", lambda tmp, out, ranks: ["-m", "pfault", OED, "-pfault_output_dir", "/proc/pfault_out"], 4,
         "-pfault_output_dir /proc/pfault_out: cannot create files in '/proc'"),
    Case("output_is_a_file", scene(), 4, "it exists and is not a directory; remove it", "file"),
    Case("output_below_a_file", lambda tmp, out, ranks: ["-m", "pfault", OED, "-pfault_output_dir",
                                                         str(out / "run")], 4, "is not a directory", "file"),
    Case("output_empty_name", lambda tmp, out, ranks: ["-m", "pfault", OED, "-pfault_output_dir", ""], 1,
         "-pfault_output_dir: empty directory name"),
    Case("output_larger_than_disk", scene("-pfault_time_steps", "1000000000000", "-pfault_box_cells", "1,1,1"), 4,
         "the output needs about", "kept"),
    # a solve that fails: exit 3
    Case("flow_not_converged", scene_file(FLOW_BOX, "-pfault_time_end", "1*day", "-pfault_time_steps", "2",
                                          "-flow_ksp_max_it", "1", "-flow_pc_type", "jacobi"), 3,
         "groundwater flow: KSP flow_ did not converge at t = 43200 s (reason -3)", "kept"),
    # the geostatic gravity solve fails: no initial stress from a wrong state (it opened the faults of the fault
    # scene at step 0 and its run went on)
    Case("gravity_solve_not_converged", scene("-pfault_geostatic", "true", "-pc_type", "jacobi", "-ksp_max_it", "1"),
         3, "-pfault_geostatic: the elastic gravity solve of the initial stress failed (KSP reason -3)", "kept"),
    Case("gravity_solve_not_converged_with_faults", lambda tmp, out, ranks: [
        "-m", "pfault", TWO_BLOCKS, "-pfault_output_dir", str(out), "-pfault_geostatic", "true",
        "-pc_type", "jacobi", "-ksp_max_it", "1"], 3,
        "-pfault_geostatic: the elastic gravity solve of the initial stress failed (KSP reason -3)", "kept"),
    # faults on one rank only (rank 1 of 2): the job ends with the line and the code
    Case("bug_on_one_rank", inject("bug", 1, 3), 6, "RuntimeError: injected fault in step 3 (a bug", "partial"),
    Case("bug_on_one_rank_before_its_first_step_is_written", inject("bug_at_step_end", 1, 1), 6,
         "RuntimeError: injected fault at the end of step 1 (a bug", "none"),
    Case("bug_on_rank_0", inject("bug", 0, 3), 6, "RuntimeError: injected fault in step 3 (a bug", "partial"),
    Case("bug_on_rank_0_before_any_step", inject("bug", 0, 1), 6, "RuntimeError: injected fault in step 1 (a bug",
         "none"),
    Case("memory_on_one_rank", inject("memory", 1, 3), 5, "out of memory (injected: unable to allocate 8 GiB",
         "partial"),
    Case("flow_failure_after_two_steps", inject("flow", 0, 3), 3, "groundwater flow: injected: KSP flow_ did not "
         "converge in step 3; the flow solver is set with -flow_ksp_*", "partial"),
    Case("disk_full_during_run", inject("disk_full", 0, 3), 4,
         "cannot write fields.h5: No space left on device; free space on that disk or choose another "
         "-pfault_output_dir", "partial"),
    # on 2 ranks the fields are written by every rank: a failure on rank 1 alone ends every rank together
    Case("disk_full_on_one_rank_during_run", inject("disk_full", 1, 3), 4,
         "cannot write fields.h5: No space left on device; free space on that disk or choose another "
         "-pfault_output_dir", "partial"),
]


def _snapshot(path):
    if not os.path.exists(path):
        return None
    if os.path.isfile(path):
        return (path.read_bytes(), os.stat(path).st_mtime_ns)
    return {p.name: (p.read_bytes(), os.stat(p).st_mtime_ns) for p in sorted(path.iterdir())}


def _prepare(case, out):
    if case.disk == "kept":
        out.mkdir()
        (out / "summary.json").write_text(json.dumps({"scene": "previous run", "converged": True}))
        (out / "fields.h5").write_bytes(np.arange(100, dtype=np.float64).tobytes())
        for p in out.iterdir():
            os.utime(p, ns=(10**18, 10**18))
    elif case.disk == "file":
        out.write_text("a file where the output directory would go\n")
        os.utime(out, ns=(10**18, 10**18))


def _error_lines(text):
    return [line for line in text.splitlines() if line.startswith(("pfault: error", "pfault: internal error"))]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(tmp_path, case, ranks):
    if case.id == "box_beyond_petsc_indices" and petsc_index_bytes() != 4:
        pytest.skip("PETSc with 64-bit indices")
    out = tmp_path / "out"
    _prepare(case, out)
    before = _snapshot(out)
    code, stdout, stderr = run_pfault(case.args(tmp_path, out, ranks), ranks)
    lines = _error_lines(stderr)
    assert code == case.code, stdout[-2000:] + stderr[-3000:]
    assert len(lines) == 1, stderr[-3000:]            # printed once, by one rank
    assert case.message in lines[0], lines[0]
    assert ("Traceback" in stderr) == (case.code == 6), stderr[-3000:]
    assert not [f for f in os.listdir(tmp_path) if ".pfault-" in f], os.listdir(tmp_path)   # no staging left
    if case.disk in ("none",):
        assert not os.path.exists(out)
    elif case.disk in ("kept", "file"):
        assert _snapshot(out) == before
    elif case.disk == "partial":
        with open(out / "summary.json") as fh:
            summary = json.load(fh)
        assert summary["completed_steps"] == [1, 2], summary
        assert not summary["running"] and summary["exit_code"] == case.code, summary
        assert summary["error"] == lines[0] and summary["converged"] == (case.code != 3)
        assert not [f for f in os.listdir(out) if f.endswith(".tmp")], os.listdir(out)
        import h5py
        with h5py.File(out / "fields.h5", "r") as h5:
            assert sorted(int(k) for k in h5["steps"]) == [0, 1, 2]
        with h5py.File(out / "checkpoint.h5", "r") as h5:
            assert h5.attrs["step"] == 2


def test_failure_on_one_rank_alone_is_recorded_and_continued(tmp_path):
    """Rank 1 of 2 fails alone in step 3 and aborts the job (rank 0, waiting in the step's collective calls, is
    stopped with it): summary.json, written by rank 1 before the abort, is that of step 2 with how the run
    ended, nothing else is left beside the run's files, and the run continues from its checkpoint to the
    analytic settlement of the oedometer (0.83333 m at t = 10 s; 1/5 of it after step 2)."""
    out = tmp_path / "out"
    code, _, stderr = run_pfault(inject("bug", 1, 3)(tmp_path, out, 2) + ["-pfault_figures", "false"], 2)
    line = ("pfault: internal error on rank 1 (the other ranks are stopped): RuntimeError: injected fault in step 3 "
            "(a bug: please report it with the command line and the traceback above)")
    assert code == 6 and _error_lines(stderr) == [line], stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["running"] is False and summary["exit_code"] == 6 and summary["error"] == line, summary
    assert summary["converged"] and not summary["interrupted"] and summary["ranks"] == 2
    assert summary["completed_steps"] == [1, 2] and [r["step"] for r in summary["steps"]] == [1, 2]
    assert summary["max_subsidence_m"] == pytest.approx(0.8333333333 / 5, rel=1e-9)
    assert sorted(os.listdir(out)) == ["checkpoint.h5", "fields.h5", "fields.xdmf", "input_files.json",
                                       "materials.json", "options.txt", "summary.json", "surface.h5", "surface.xdmf",
                                       "versions.json"]
    assert sorted(os.listdir(tmp_path)) == ["out"]
    code, _, stderr = run_pfault(["-m", "pfault", OED, "-pfault_restart", str(out), "-pfault_figures", "false"], 2)
    assert code == 0, stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed_steps"] == list(range(1, 11)) and summary["restart"]["step"] == 2
    assert not summary["running"] and "error" not in summary and "exit_code" not in summary
    assert summary["max_subsidence_m"] == pytest.approx(0.8333333333, rel=1e-9)


def test_catalogue_size():
    assert len(CASES) >= 40


def test_box_larger_than_memory(tmp_path):
    """A box whose serial mesh alone would not fit in memory is refused before numpy allocates it."""
    from pfault.checks import available_memory
    avail = available_memory()
    if avail is None or avail > 300e9:
        pytest.skip("needs a machine with less than 300 GB available")
    out = tmp_path / "out"
    code, _, stderr = run_pfault(scene("-pfault_box_cells", "700,700,700")(tmp_path, out, 1), 1)
    lines = _error_lines(stderr)
    assert code == 5 and len(lines) == 1, stderr
    assert lines[0].startswith("pfault: error: -pfault_box_cells 700,700,700: building the mesh alone needs about "
                               "343 GB, more than the "), lines[0]
    assert lines[0].endswith("GB of memory available; use fewer cells"), lines[0]
    assert not out.exists()


@pytest.mark.parametrize("ranks", [1, 2])
def test_duplicate_option_in_one_file_warns(tmp_path, ranks):
    """An option twice in the same file: one warning naming the value used; the run goes on."""
    path = write(tmp_path / "scene.opts", f"-options_file {OED_FILE}\n-pfault_time_steps 2\n# later\n-pfault_time_steps 3\n")
    code, stdout, stderr = run_pfault(["-m", "pfault", path, "-pfault_output_dir", str(tmp_path / "out")], ranks)
    assert code == 0, stderr
    warnings = [line for line in stderr.splitlines() if line.startswith("pfault: warning")]
    assert warnings == [f"pfault: warning: -pfault_time_steps is given 2 times in {path} (lines 2, 4); the value "
                        "used is '3'"]
    with open(tmp_path / "out" / "summary.json") as fh:
        assert len(json.load(fh)["steps"]) == 3


def test_input_warnings_are_printed_once_and_kept(tmp_path):
    """The oedometer's table in bare seconds (0:0,10:-0.1*MPa) under a run of 10*year, and a modulus map whose grid
    misses a node, on 2 ranks: each warning printed once, both in summary.json; the run completes with the whole
    load at the first step (the analytic settlement 0.83333 m at every step; the map is 10 MPa everywhere)."""
    field = write(tmp_path / "map.csv", "x,y,E [MPa]\n0,0,10\n10,0,10\n0,10,10\n10,10,10\n5,0,10\n5,10,10\n"
                                        "0,5,10\n10,5,10\n")                   # a 3 x 3 grid without (5, 5)
    out = tmp_path / "out"
    code, _, stderr = run_pfault(["-m", "pfault", OED, "-pfault_output_dir", str(out), "-pfault_time_end", "10*year",
                                  "-pfault_time_steps", "2", "-pfault_figures", "false",
                                  "-pfault_material_soil_young_modulus", f"field:{field}"], 2)
    assert code == 0, stderr
    warnings = [line for line in stderr.splitlines() if line.startswith("pfault: warning")]
    assert warnings == [
        "pfault: warning: -pfault_material_soil_pressure_change: the table ends at t = 10 s, before the run's first "
        "step (t = 5 year): every step takes its last value and the run sees none of its changes; its times have no "
        "unit, so they are seconds: give them in the run's unit (e.g. 10*year)",
        f"pfault: warning: -pfault_material_soil_young_modulus field:{field}: the 8 points lie on the 3 x 3 grid of "
        "their distinct x, y values but leave 1 of its nodes empty (e.g. x = 5, y = 5); they are read as scattered "
        "points (linear between neighbouring points), not as a grid; give every node of the grid once for "
        "(multi)linear interpolation on it"], stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["warnings"] == warnings
    assert [r["max_subsidence_m"] for r in summary["steps"]] == pytest.approx([0.8333333333] * 2, rel=1e-9)


def test_command_line_override_and_duplicates(tmp_path):
    """The command line overriding the scene says nothing; an option twice on the command line warns."""
    out = str(tmp_path / "out")
    code, _, stderr = run_pfault(["-m", "pfault", OED, "-pfault_output_dir", out, "-pfault_time_steps", "2"], 1)
    assert code == 0 and "warning" not in stderr
    code, _, stderr = run_pfault(["-m", "pfault", OED, "-pfault_output_dir", out, "-pfault_time_steps", "2",
                                  "-pfault_time_steps", "1"], 1)
    assert code == 0
    assert [line for line in stderr.splitlines() if "warning" in line] == [
        "pfault: warning: -pfault_time_steps is given 2 times on the command line; the value used is '1'"]


def test_free_rigid_motions():
    """The rigid-body check on the corners of a unit cube: which motions the constrained components leave free."""
    from pfault.checks import free_rigid_motions
    x = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float) * 100.0 + 5e5
    mask = np.zeros(8, dtype=np.int64)
    assert free_rigid_motions(x, mask) == ([0, 1, 2], [0, 1, 2], 6)
    mask[0] = 7                                   # one point fixed: rotations about it
    assert free_rigid_motions(x, mask) == ([], [0, 1, 2], 3)
    mask[4] = 7                                   # a second one on the x axis through it: rotation about x
    assert free_rigid_motions(x, mask) == ([], [0], 1)
    mask[2] = 7                                   # a third, off that axis: held
    assert free_rigid_motions(x, mask) == ([], [], 0)
    bottom = np.where(x[:, 2] == x[:, 2].min(), 4, 0)    # uz on the plane z = min: x, y and rotation about z
    assert free_rigid_motions(x, bottom) == ([0, 1], [2], 3)
