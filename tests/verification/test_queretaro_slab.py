"""Queretaro's fault in plane strain (studies/queretaro_slab.py: the section across config/queretaro.opts's fault as a
slab one element thick, the sand drawn down, 1 rank, MUMPS). Under calibrated Queretaro's load (11.3 m of head
beside the fault at year 10) the fault's slipping and open zone is the top row of faces at every element size, and
its integrals vanish under refinement: the fault does not slide or open in the continuum, and what a mesh shows is
that mesh's top row. Under seven times the load (the stated pumping) the whole fault slides or opens and the answer
converges. docs/verification.md gives the whole series (8 m to 0.25 m)."""

import pytest

from conftest import run_scene
from studies.queretaro_slab import make_case, measures


def _run(tmp_path, h, drawdown):
    out = tmp_path / f"h{h}-dd{drawdown}"
    scene = make_case(str(out), h, drawdown)
    _, s = run_scene(scene, out, extra=[])
    assert s["converged"]
    return measures(str(out), h)


def test_calibrated_load_slides_and_opens_only_the_top_row(tmp_path):
    """Measured at h = 2, 1, 0.5 m: open length 2 / 1 / 0.5 m (the top face), slipping length 0 / 0.5 / 0.25 m, the
    potency 8.16e-3 / 2.62e-3 / 8.5e-4 m^3/m (3.1 times less per halving, rate 1.6) and the open volume 7.37e-3 /
    2.86e-3 / 9.7e-4 m^3/m (2.6 and 3.0 times less): a quantity with a positive limit would change less and less.
    Asserted: the open zone exactly the top row of faces, nothing below two rows, each integral at least 2.2 times
    less per halving."""
    m = {h: _run(tmp_path, h, "11.3") for h in (2.0, 1.0, 0.5)}
    for h, r in m.items():
        assert r["open_length"] == pytest.approx(h, rel=1e-9), (h, r)
        assert r["open_depth"] == pytest.approx(h, rel=1e-9) and r["slip_depth"] <= 2 * h + 1e-9, (h, r)
    for coarse, fine in ((2.0, 1.0), (1.0, 0.5)):
        for key in ("potency", "open_volume"):
            assert m[coarse][key] >= 2.2 * m[fine][key] > 0.0, (key, coarse, m[coarse][key], m[fine][key])


def test_stated_load_slides_the_whole_fault_and_converges(tmp_path):
    """80 m of drawdown: every face slips (upper 26 m) or opens (to 43 m), potency 36.21 / 35.94 m^3/m at h = 1 /
    0.5 m (0.75 %), open volume 1.179 / 1.195 m^3/m (1.3 %), largest slip 1.078 m at both. Asserted: the whole 50 m
    fault slipping or open, potency and open volume within 2 %, largest slip within 0.5 %."""
    m = {h: _run(tmp_path, h, "80") for h in (1.0, 0.5)}
    for h, r in m.items():
        assert r["slip_length"] + r["open_length"] == pytest.approx(50.0, rel=1e-9), (h, r)
        assert r["potency"] > 30.0, (h, r)
    assert m[0.5]["potency"] == pytest.approx(m[1.0]["potency"], rel=0.02)
    assert m[0.5]["open_volume"] == pytest.approx(m[1.0]["open_volume"], rel=0.02)
    assert m[0.5]["max_slip"] == pytest.approx(m[1.0]["max_slip"], rel=0.005)
