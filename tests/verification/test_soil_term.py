"""The law with memory in the finite-element equations (pfault.soils.term; tests/scripts/soil_checks.py, in-process
on 1 and 2 ranks): a laterally confined column against the closed form of the compression-index law and CSUB's
no-delay relation, and the Taylor test of the term's Jacobian with cells on both branches and at the switch."""

import pytest

from conftest import run_script

RANKS = (1, 2)


@pytest.fixture(scope="module", params=RANKS)
def checks(request):
    return run_script("soil_checks.py", ranks=request.param)


def test_column_is_the_closed_form_whatever_the_steps(checks):
    """The FE column (40 layers of cells, each from its layer's uniform initial stress) after each drawdown stage
    (loading past the preconsolidation, unloading, reloading past the earlier maximum, unloading): the closed-form
    integral of the index law within 1e-6 (measured 5e-13) at one and at four steps per stage; CSUB's no-delay
    relation with the equivalent storage values within 1e-6 of both (MODFLOW 6's 0.4342942 for 1/ln 10: 6.5e-7).
    With CSUB's head-based storages: CSUB's HEAD_BASED relation to round-off."""
    for per_stage in (1, 4):
        c = checks[f"column_index_{per_stage}"]
        assert c["fe_closed_form"] < 1e-6
        assert c["csub_closed_form"] < 1e-6 and c["fe_csub"] < 1e-6
        fe = c["fe"]
        assert fe[1] > fe[0] > 0.1 and fe[2] < fe[1] and fe[3] > fe[1] and fe[4] < fe[3]
        s = checks[f"column_storage_{per_stage}"]
        assert s["fe_closed_form"] < 1e-10 and s["fe_csub"] < 1e-10
    one, four = checks["column_index_1"]["fe"], checks["column_index_4"]["fe"]
    assert max(abs(a / b - 1) for a, b in zip(one, four)) < 1e-10


def test_jacobian_is_the_consistent_tangent(checks):
    """Taylor remainder |F(x + h v) - F(x) - h J v| of the whole residual (elastic skeleton and the term) at h =
    1e-2, 1e-3, 1e-4: order 2 (1.95-2.05 per decade) from a state with cells compacting on the virgin line, cells
    on their swelling line unloaded from their cap or below it, and cells crossing their cap within the step (each
    kind present, none changing branch along h v); at the switch (the normally consolidated cells on their cap, no
    strain increment yet): order 2 unloading with the residual's own (elastic) Jacobian, order 1 loading with it
    (the kink), order 2 loading with the virgin branch's (the semismooth Newton's other generalised derivative)."""
    mixed = checks["taylor_mixed"]
    assert all(n >= 10 for n in mixed["cells"].values()), mixed["cells"]
    assert mixed["cells_off_branch"] == 0
    assert all(1.95 < o < 2.05 for o in mixed["order2"]), mixed["order2"]
    assert checks["taylor_switch_cells_on_cap"] > 50
    unload = checks["taylor_switch_unloading"]
    assert unload["cells_off_branch"] == 0 and all(1.95 < o < 2.05 for o in unload["order2"])
    assert all(0.95 < o < 1.05 for o in checks["taylor_switch_loading_elastic"]["order2"])
    assert 1.95 < checks["taylor_switch_loading_virgin"]["order2"][-1] < 2.05
