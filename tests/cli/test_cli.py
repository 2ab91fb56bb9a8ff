"""Command line: help, bad input (one clear line, every rank, non-zero exit, nothing written)."""

import os

import pytest

from conftest import OEDOMETER, REPO, read_summary, run, run_scene


def test_help_lists_every_option():
    proc = run(["-m", "pfault", "-help"])
    from pfault.options import SPECS
    for spec in SPECS:
        assert f"-{spec.name}" in proc.stdout
    assert "[Pa]" in proc.stdout and "default" in proc.stdout


def test_help_lists_the_exit_codes():
    proc = run(["-m", "pfault", "-help"])
    from pfault.errors import EXIT_CODES
    assert [code for code, _ in EXIT_CODES] == list(range(8))
    for code, text in EXIT_CODES:
        assert f"  {code}  {text}" in proc.stdout
    assert "  4  the output cannot be written" in proc.stdout and "  7  interrupted" in proc.stdout


def test_no_scene_is_usage_error():
    proc = run(["-m", "pfault"], check=False)
    assert proc.returncode == 2 and "usage" in proc.stderr


def test_missing_scene_file():
    proc = run(["-m", "pfault", "config/no_such_scene.opts"], check=False)
    assert proc.returncode == 2
    assert "config/no_such_scene.opts" in proc.stderr


BAD = [
    (["-pfault_bc_top_typ", "free"], "-pfault_bc_top_typ; did you mean -pfault_bc_top_type?"),
    (["-ksp_rtoll", "1e-3"], "unused option -ksp_rtoll"),
    (["-pfault_material_sand_young_modulus", "1e6"], "unused option -pfault_material_sand_young_modulus"),
    (["-pfault_material_soil_poisson_ratio", "0.7"], "-pfault_material_soil_poisson_ratio: must lie in (-1, 0.5)"),
    (["-pfault_time_end", "10*years"], "unknown unit 'years'"),
    (["-pfault_bc_top_type", "clamped"], "-pfault_bc_top_type: 'clamped' is not one of"),
    (["-pfault_mesh_file", "nowhere.msh"], "-pfault_mesh_file nowhere.msh: no such file; give a gmsh MSH 4.1 file"),
    (["-pfault_solver", "superfast"], "-pfault_solver superfast"),
    (["-pfault_contact_slip_augmentation", "0.01"], "unused option -pfault_contact_slip_augmentation"),
    (["-pfault_time_max_cuts", "-1"], "-pfault_time_max_cuts: give 0 to 10 halvings"),
]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("extra,message", BAD)
def test_bad_input(tmp_path, ranks, extra, message):
    out = tmp_path / "out"
    proc, summary = run_scene(OEDOMETER, out, ranks=ranks, extra=extra, check=False)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("pfault: error:")]
    assert len(lines) == 1, proc.stderr       # printed once, not once per rank
    assert message in lines[0]
    assert "Traceback" not in proc.stderr
    assert not os.path.exists(out)            # nothing written


def test_missing_material_property(tmp_path):
    scene = tmp_path / "s.opts"
    scene.write_text("-pfault_box_cells 1,1,1\n-pfault_box_materials sand\n")
    proc, _ = run_scene(str(scene), tmp_path / "out", check=False)
    assert proc.returncode == 1
    assert "missing -pfault_material_sand_young_modulus (Pa)" in proc.stderr


def test_command_line_overrides_scene_file(tmp_path):
    _, summary = run_scene(OEDOMETER, tmp_path, extra=["-pfault_time_steps", "2",
                                                                     "-pfault_box_cells", "1,1,4"])
    assert len(summary["steps"]) == 2
    assert summary["mesh"]["cells"] == 6 * 4
    text = (tmp_path / "options.txt").read_text()
    assert "-pfault_time_steps 2" in text
    assert (tmp_path / "versions.json").exists()


def test_krylov_method_chosen_over_a_solver_file(tmp_path):
    """-ksp_type on the command line replaces the solver file's Krylov method, and the file's options of that
    method (iterative.opts: -ksp_gmres_restart) do not make the run fail as unused options."""
    _, summary = run_scene(OEDOMETER, tmp_path, extra=["-pfault_solver", "iterative",
                                                                     "-ksp_type", "cg"])
    assert summary["converged"]
    assert summary["solver"]["ksp_type"] == "cg"
    assert summary["solver"]["pc_type"] == "hypre"       # the displacement split's (no fault)


def test_included_file_is_found_beside_the_including_file(tmp_path):
    """A scene including another by a relative path runs from any directory: the include is found beside the
    file that includes it (an absolute include as it is), and the later value wins as in PETSc."""
    scenes, elsewhere = tmp_path / "scenes", tmp_path / "elsewhere"
    scenes.mkdir()
    elsewhere.mkdir()
    (scenes / "base.opts").write_text(f"-options_file {os.path.join(REPO, OEDOMETER)}\n-pfault_time_steps 3\n")
    (scenes / "variant.opts").write_text("-options_file base.opts\n-pfault_time_steps 2\n")
    proc = run(["-m", "pfault", os.path.join("..", "scenes", "variant.opts"),
                "-pfault_output_dir", "out", "-pfault_figures", "false"], timeout=120, cwd=elsewhere, check=False)
    assert proc.returncode == 0, proc.stderr
    summary = read_summary(elsewhere / "out")
    assert [r["step"] for r in summary["steps"]] == [1, 2]
    assert summary["scene"] == "oedometer"


@pytest.mark.parametrize("variant, base_scene, own_scene", [("wuxi_recovery.opts", "wuxi_inelastic", "wuxi_recovery"),
                                                             ("wuxi_recovery_elastic.opts", "wuxi",
                                                              "wuxi_recovery_elastic"),
                                                             ("wuxi_fissure.opts", "wuxi", "wuxi_fissure"),
                                                             ("queretaro_calibrated.opts", "queretaro",
                                                              "queretaro_calibrated")])
def test_shipped_variants_read_from_another_directory(tmp_path, monkeypatch, variant, base_scene, own_scene):
    """config's variants include their base scene beside them: from another working directory their options
    are the base's, then their own (the later -pfault_scene wins)."""
    from pfault.optionsfile import petsc_arguments
    monkeypatch.chdir(tmp_path)
    args = petsc_arguments(os.path.join(REPO, "config", variant), ["-pfault_time_steps", "1"])
    scenes = [args[i + 1] for i, a in enumerate(args) if a == "-pfault_scene"]
    assert scenes == [base_scene, own_scene]
    assert args[-2:] == ["-pfault_time_steps", "1"]


def test_missing_include_names_where_it_was_looked_for(tmp_path, monkeypatch):
    """An include that is not beside its file but is in the working directory: the error says where it was
    looked for and how to write it."""
    from pfault.optionsfile import ArgumentError, read_options_file
    monkeypatch.chdir(REPO)
    scene = tmp_path / "scene.opts"
    scene.write_text(f"-options_file {OEDOMETER}\n")
    with pytest.raises(ArgumentError) as err:
        read_options_file(str(scene))
    assert str(err.value) == (f"{scene} line 1: -options_file {OEDOMETER}: no such file (an included file is "
                              f"found relative to the file that includes it, in {tmp_path}; {OEDOMETER} of the "
                              f"working directory is {os.path.relpath(os.path.join(REPO, OEDOMETER), tmp_path)} "
                              "from there)")
    assert err.value.code == 1
