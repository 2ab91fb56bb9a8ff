"""Modified Cam-Clay reduced to the oedometer against the 1-D compression-index law (studies/soil_laws.py), the
figures docs/theory.md quotes: with a friction-based M its virgin line has the index law's slope but its K0 is not
nu/(1-nu) and its oedometric rebound falls short of the index law's; with the M that holds K0 = nu/(1-nu) it is the
index law on unloading too."""

import pytest

from studies import soil_laws as cam


def test_cam_clay_with_m_of_30_degrees_rebounds_less():
    r = cam.measure(cam.m_from_friction(30), False)
    assert r["virgin slope / Cc"] == pytest.approx(1.0, abs=1e-3)
    assert r["K0"] == pytest.approx(0.655, abs=0.005)
    assert r["rebound OCR 2 / index law"] == pytest.approx(0.742, abs=0.005)
    assert r["rebound OCR 8 / index law"] == pytest.approx(0.585, abs=0.005)
    assert not r["yields unloading to OCR 8"]


def test_cam_clay_with_the_k0_m_is_the_index_law():
    """M^2 = eta^2 + 3 eta, eta = 3(1-2nu)/(1+nu): K0 = nu/(1-nu) on the virgin line and the index law's rebound
    (within the 1e-4 of the explicit integration)."""
    r = cam.measure(cam.m_for_k0(), False)
    assert r["K0"] == pytest.approx(cam.NU / (1 - cam.NU), abs=1e-3)
    for ocr in (2, 4, 8):
        assert r[f"rebound OCR {ocr} / index law"] == pytest.approx(1.0, abs=2e-3)
