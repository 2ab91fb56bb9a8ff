"""The constant operator built block by block (pfault.solver.operator.build_blocked: exactly the 3x3 blocks the cells
and the terms touch) against the DM's matrix extended by the terms' pattern, which it replaced: the same entries,
block size 3, and every entry of the DM's matrix that holds a value inside the new pattern; with faults fewer
entries than the DM's adjacency preallocates (a face's multipliers reach the vertices and faces the interface
blocks couple, not every point of the faces' cells' closures)."""
import pytest

from conftest import run_script


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("scene,faults", [("config/two_blocks.opts", True), ("config/hard/fissure_box.opts", True),
                                          ("config/soil_column.opts", False)])
def test_blocked_operator_equals_the_dm_operator(scene, faults, ranks):
    out = run_script("operator_check.py", ranks=ranks, args=["--scene", scene])
    assert out["ranks"] == ranks
    assert out["rel_diff"] < 1e-14, out
    assert out["missing"] == 0, out
    assert out["bs"] == 3, out
    assert 0 < out["nnz"] <= out["nnz_dm"], out
    assert (out["nnz"] < out["nnz_dm"]) == faults, out
