"""Soils that remember on 1 and 2 ranks, alone and with a fault: the same answer on both (1e-10), and a restart across
the loading/unloading switch equal to the uninterrupted run.

config/soil_column.opts (5 stages: loading past the preconsolidation, further, unloading, reloading past the earlier
maximum, unloading): 1 against 2 ranks; stopped after the unloading (step 3, every cell back on its swelling line)
and continued through the reloading past the earlier maximum (every cell back on the virgin line), on 1 and 2 ranks.
A faulted box with soils (the equations' two terms: the fault's faces and the soils' cells; the block beyond the
fault pulled away by a prescribed displacement, so that faces slip while cells compact on the virgin line, and
open while the heads recover and every cell swells): 1 against 2 ranks, and its restart across the
recovery.
A fault beside soils compacting on the virgin line: config/faulted_aquifer.opts on its 40 m slice at size factor 3,
its sand normally consolidated with Cc 0.05, Cr 0.01: one 1 m drawdown step from the geostatic start converges in
a few Newton iterations on 1 and 2 ranks (with the face bubbles of the sand at its swelling line's bulk modulus,
every sand cell beside the fault was indefinite on the virgin line: 72 Newton iterations, 8 sub-steps on 1 rank, 67
on 2; at size factor 2 the step failed after 93).
"""

import numpy as np
import pytest

from conftest import compare_runs, run_scene, soil_aquifer_slice

COLUMN = "config/soil_column.opts"
FAULTED = """# a box with a fault and soils that remember: the equations' two terms
-pfault_scene faulted_soils
-pfault_mesh_generator box
-pfault_box_size 400,100,100
-pfault_box_cells 16,4,10
-pfault_box_materials clay,sand,rock
-pfault_box_interfaces 20,60
-pfault_box_fault_planes fissure:x:375:0:100:-50:0
-pfault_material_clay_compression_index 0.25
-pfault_material_clay_recompression_index 0.04
-pfault_material_clay_void_ratio 0.9
-pfault_material_clay_poisson_ratio 0.3
-pfault_material_clay_density 1900
-pfault_material_sand_compression_index 0.05
-pfault_material_sand_recompression_index 0.01
-pfault_material_sand_void_ratio 0.7
-pfault_material_sand_poisson_ratio 0.3
-pfault_material_sand_density 2000
-pfault_material_rock_young_modulus 1200*MPa
-pfault_material_rock_poisson_ratio 0.3
-pfault_material_rock_density 2400
-pfault_faults fissure
-pfault_fault_fissure_friction_angle 30
-pfault_bc_bottom_type fixed
-pfault_bc_xmax_type displacement
-pfault_bc_xmax_components x
-pfault_bc_xmax_displacement 0.5,0,0
-pfault_bc_xmax_history 0:0,4*year:1
-pfault_bc_xmin_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_geostatic true
-pfault_material_sand_head_drawdown 0:0,2*year:20,4*year:5
-pfault_material_clay_head_drawdown 0:0,2*year:10,4*year:2
-pfault_time_end 4*year
-pfault_time_steps 4
-pfault_solver mumps
"""
EXACT = ["-ksp_atol", "0", "-ksp_rtol", "1e-12"]        # Krylov solves to round-off: runs agree to it


@pytest.fixture(scope="module")
def faulted(tmp_path_factory):
    path = tmp_path_factory.mktemp("faulted") / "faulted_soils.opts"
    path.write_text(FAULTED)
    return str(path)


@pytest.fixture(scope="module")
def column_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("column")
    return {ranks: (base / f"r{ranks}", run_scene(COLUMN, base / f"r{ranks}", ranks=ranks, extra=EXACT)[1])
            for ranks in (1, 2)}


def test_column_on_one_and_two_ranks(column_runs):
    (one, s1), (two, s2) = column_runs[1], column_runs[2]
    assert s1["converged"] and s2["converged"] and s2["ranks"] == 2
    virgin = [r["cells_virgin"] for r in s1["steps"] if not r.get("initial")]
    assert virgin[1] == virgin[3] == 234 and virgin[2] == virgin[4] == 0      # loading, unloading, reloading
    compare_runs(one, two, 1e-10)
    # the smallest head margin of the cells (a MIN over the ranks): 0 on the virgin line, then the unloading's rebound
    m1, m2 = ([[r["soils"][k]["min_head_margin_m"] for k in sorted(r["soils"])] for r in s["steps"]] for s in (s1, s2))
    assert np.allclose(m1, m2, rtol=0, atol=1e-9) and np.allclose(m1[3], [7.0, 7.0, 14.0], rtol=0, atol=1e-9), m1
    assert np.allclose(m1[2], 0.0, atol=1e-9) and abs(s1["min_head_margin_m"]) < 1e-9


@pytest.mark.parametrize("ranks", [1, 2])
def test_restart_across_the_switch(column_runs, tmp_path, ranks):
    ref, _ = column_runs[ranks]
    part = tmp_path / "part"
    run_scene(COLUMN, part, ranks=ranks, extra=[*EXACT, "-pfault_time_end", "3*year", "-pfault_time_steps", "3"])
    _, s = run_scene(COLUMN, part, ranks=ranks, extra=[*EXACT, "-pfault_restart", str(part)])
    assert s["completed_steps"] == [1, 2, 3, 4, 5] and s["restart"]["step"] == 3
    compare_runs(ref, part, 1e-12 if ranks == 1 else 1e-10)


def test_faults_and_soils_together(faulted, tmp_path):
    """Both terms in one run: the faces' counts and the cells' in every step's record, on 1 and 2 ranks alike
    (1e-10), and a restart after the first recovery step equal to the uninterrupted run."""
    runs = {r: run_scene(faulted, tmp_path / f"r{r}", ranks=r, extra=EXACT)[1] for r in (1, 2)}
    steps = [r for r in runs[1]["steps"] if not r.get("initial")]
    assert all({"stick", "slip", "open", "cells_virgin", "cells_elastic"} <= set(r) for r in steps)
    assert steps[1]["cells_virgin"] > 0 and steps[1]["slip"] > 0
    assert steps[2]["cells_virgin"] == 0 and steps[2]["open"] > 0 and steps[3]["open"] > 0  # every cell swells
    assert runs[1]["soils"]["clay"]["max_compaction_inelastic"] > 0 and "faults" in runs[1]
    compare_runs(tmp_path / "r1", tmp_path / "r2", 1e-10)
    part = tmp_path / "part"
    run_scene(faulted, part, ranks=2, extra=[*EXACT, "-pfault_time_end", "3*year", "-pfault_time_steps", "3"])
    _, s = run_scene(faulted, part, ranks=2, extra=[*EXACT, "-pfault_restart", str(part)])
    assert s["completed_steps"] == [1, 2, 3, 4]
    compare_runs(tmp_path / "r2", part, 1e-10)


def test_flow_model_with_soils(tmp_path):
    """The flow model with a material with memory (the flow box's soil given indices, no drained modulus): its default
    specific storage is its cells' elastic skeletal storage at their reference modulus (it was NaN before: the flow's
    solve diverged), and the drawdown compacts it on the virgin line."""
    from conftest import FLOW_BOX
    scene = FLOW_BOX.replace("-pfault_material_soil_young_modulus 10*MPa",
                             "-pfault_material_soil_compression_index 0.2\n-pfault_material_soil_recompression_index "
                             "0.03\n-pfault_material_soil_void_ratio 0.8\n-pfault_material_soil_density 2000\n"
                             "-pfault_geostatic true")
    path = tmp_path / "flow_soil.opts"
    path.write_text(scene + "-pfault_time_end 2*day\n-pfault_time_steps 2\n")
    _, s = run_scene(str(path), tmp_path / "out")
    steps = [r for r in s["steps"] if not r.get("initial")]
    assert s["converged"] and steps[-1]["cells_virgin"] == 48 and steps[-1]["max_drawdown_m"] > 0
    assert 0 < s["max_subsidence_inelastic_m"] < s["max_subsidence_m"]


@pytest.fixture(scope="module")
def aquifer_slice(tmp_path_factory):
    """The faulted aquifer's 40 m slice at size factor 3 (583 tetrahedra, 219 of them sand, 30 fault faces), its
    sand given compression indices, and the options of one 1 m drawdown step."""
    scene, msh = soil_aquifer_slice(tmp_path_factory.mktemp("aquifer_slice"), 3, "aquifer_soil.opts")
    return scene, ["-pfault_mesh_file", msh, "-pfault_material_sand_head_drawdown", "0:0,1*year:1",
                        "-pfault_time_end", "1*year", "-pfault_time_steps", "1"]


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_step_compacting_beside_a_fault_converges(aquifer_slice, tmp_path, ranks):
    """One 1 m step from the geostatic start: every sand cell compacts on the virgin line, every face sticks, and
    Newton converges with no sub-step in at most 15 iterations (4 measured: quadratic from the elastic trial)."""
    scene, extra = aquifer_slice
    _, s = run_scene(scene, tmp_path / "out", ranks=ranks, extra=extra)
    step = s["steps"][-1]
    assert s["converged"] and step["converged"] and "substeps" not in step
    assert step["newton_its"] <= 15
    assert step["cells_virgin"] == 219 and step["cells_elastic"] == 0 and step["stick"] == 30


def test_soils_and_faults_on_the_iterative_solver_with_margins(tmp_path):
    """Wuxi with soils that remember on the iterative solver, 2 ranks (the preconditioner kept across a step's
    Newton iterations while only the soils' moduli vary): every step converges, and at every output time the
    margins' linear solve on the same KSP converges where a face can still fail (it asks the reuse to set its
    iterations aside)."""
    _, s = run_scene("config/wuxi_inelastic.opts", tmp_path / "out", ranks=2,
                     extra=["-pfault_mesh_size_factor", "4", "-pfault_time_steps", "3", "-pfault_solver", "iterative"])
    steps = [st for st in s["steps"] if not st.get("initial")]
    assert s["converged"] and len(steps) == 3 and all(st["converged"] for st in steps)
    solved = [st["margin_solve"] for st in s["steps"] if st["margin_solve"]["solved"]]
    assert len(solved) >= 2 and all(m["converged"] and m["ksp_its"] > 0 for m in solved), steps
    assert s["max_subsidence_m"] == pytest.approx(1.12032, rel=1e-4)
