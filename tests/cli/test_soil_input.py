"""Bad input of the materials with memory through the command line on 2 ranks: exit code 1, one line on stderr naming
the option and the fix, printed once, no traceback, no output directory. The options are read and checked on every
rank (pfault.scene.read_soils); a preconsolidation below a cell's initial stress is found once the initial stress is
known, on the cells of every rank, and reported by all of them together (pfault.soils.measures.check_start)."""

import os

import pytest

from conftest import REPO, run

COLUMN = "config/soil_column.opts"
CASES = {
    "recompression_not_below": (["-pfault_material_clay1_recompression_index", "0.4"],
                                "-pfault_material_clay1_recompression_index: 0.4 is not below "
                                "-pfault_material_clay1_compression_index 0.35"),
    "void_ratio_not_positive": (["-pfault_material_sand_void_ratio", "0"],
                                "-pfault_material_sand_void_ratio: must be positive, got 0"),
    "modulus_and_indices": (["-pfault_material_sand_young_modulus", "12*MPa"],
                            "-pfault_material_sand_young_modulus: 'sand' has -pfault_material_sand_compression_index"),
    "preconsolidation_below_the_initial_stress": (
        ["-pfault_material_clay1_overconsolidation_ratio", None, "-pfault_material_clay1_preconsolidation_stress",
         "100*kPa"],
        "-pfault_material_clay1_preconsolidation_stress: 36 of 54 cells of 'clay1' start above their "
        "preconsolidation"),
    "symmetric_krylov": (["-pfault_solver", "gamg"], "-ksp_type cg: a method for symmetric operators, and the "
                                                      "materials with memory (clay1, sand, clay2) give a non-symmetric "
                                                      "tangent"),
}


def scene(tmp_path, extra):
    """The column with ``extra`` (a None value removes the column's option): an options file in tmp_path."""
    removed = {extra[i] for i in range(0, len(extra), 2) if extra[i + 1] is None}
    lines = [line for line in open(os.path.join(REPO, COLUMN)).read().splitlines()
             if not any(line.startswith(name + " ") for name in removed)]
    lines += [f"{extra[i]} {extra[i + 1]}" for i in range(0, len(extra), 2) if extra[i + 1] is not None]
    path = tmp_path / "scene.opts"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


@pytest.mark.parametrize("case", sorted(CASES))
def test_soil_input_error_on_two_ranks(tmp_path, case):
    extra, message = CASES[case]
    out = tmp_path / "out"
    proc = run(["-m", "pfault", scene(tmp_path, extra), "-pfault_output_dir", str(out)], 2, timeout=120,
               check=False)
    lines = [line for line in proc.stderr.splitlines() if line.startswith("pfault: error:")]
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert len(lines) == 1 and message in lines[0], proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert not out.exists()
