"""A laterally confined column of compressible layers (studies/soil_column.py): clay (OCR 1.3) over sand over clay
(preconsolidated 3 m below the initial heads) under drawdown stages that load past the preconsolidation, unload,
reload past the earlier maximum and unload again. Side by side: the closed-form integral of the compression-index law
over depth, pfault's soil law driven through the oedometric path at Gauss points, and MODFLOW 6 CSUB's no-delay
interbed relation in head units (with the equivalent storage values, and as MODFLOW 6 evaluates its storage)."""

import numpy as np
import pytest
from scipy.integrate import quad

from studies import soil_column as sc


@pytest.fixture(scope="module")
def column():
    layers, dd = sc.example_column()
    return layers, dd, sc.settlement(layers, dd)


def quad_settlement(layers, dd):
    largest = np.maximum.accumulate(np.maximum(dd, 0.0), axis=0)
    out = []
    for k in range(len(dd)):
        total = 0.0
        for j, ly in enumerate(layers):
            pts = sc.breakpoints(ly, largest[k, j])
            total += quad(lambda z: float(sc.point_strain(ly, z, largest[k, j], dd[k, j])), 0.0, ly.thickness,
                          points=pts or None, epsabs=0, epsrel=1e-13, limit=200)[0]
        out.append(total)
    return np.array(out)


def test_closed_form_against_adaptive_quadrature(column):
    """The closed form against scipy's adaptive quadrature of the point strain, for the column and for the same
    column reaching the land surface (sigma'_0 = 0 at the top: an integrable logarithmic singularity)."""
    layers, dd, exact = column
    assert np.abs(quad_settlement(layers, dd) / exact - 1).max() < 1e-10
    assert exact[1] > exact[0] > 0.1 and exact[2] < exact[1] and exact[3] > exact[1]     # load, unload, reload past
    surface = [sc.Layer(0.0, 20.0, 0.0, 9.8e3, cc=0.35, cr=0.05, e0=0.95)] + layers[1:]
    assert np.abs(quad_settlement(surface, dd) / sc.settlement(surface, dd) - 1).max() < 1e-8


def test_pfault_law_is_the_closed_form_whatever_the_steps(column):
    """pfault's soil law at 24 Gauss points per smooth piece, each stage in 1 or 7 steps: the closed form within
    1e-9 (the target is 1e-6)."""
    layers, dd, exact = column
    for substeps in (1, 7):
        got = sc.kernel_settlement(layers, dd, substeps=substeps)
        assert np.abs(got / exact - 1).max() < 1e-9, substeps


def test_csub_nodelay_relation_side_by_side(column):
    """CSUB's no-delay relation with the equivalent storage values (at the logarithmic mean stress of each branch)
    is the closed form up to MODFLOW 6's constant 0.4342942 for 1/ln 10 (6.5e-7 relative); with the storage at the
    end of each step, as MODFLOW 6 computes it, it errs by 11-18 % at one step per stage and converges at first order
    (error x 1/10 per 10x steps)."""
    layers, dd, exact = column
    eq = sc.csub_settlement(layers, dd, "equivalent")
    offset = 1 - sc.DLOG10ES * np.log(10)
    assert offset == pytest.approx(6.5e-7, rel=0.01)
    assert np.abs(eq / exact - 1 + offset).max() < 1e-10
    err = [np.abs(sc.csub_settlement(layers, dd, "current", steps) / exact - 1).max() for steps in (1, 10, 100)]
    assert 0.1 < err[0] < 0.2
    assert 8.0 < err[1] / err[2] < 12.0


def test_storage_form_is_csub_head_based():
    """With CSUB's head-based skeletal storage (Sske, Sskv per layer): pfault's law, CSUB's relation and the closed
    form agree to round-off, at one step per stage."""
    layers, dd = sc.example_column(storage=True)
    exact = sc.settlement(layers, dd)
    assert np.abs(sc.kernel_settlement(layers, dd) / exact - 1).max() < 1e-12
    assert np.abs(sc.csub_settlement(layers, dd, "head") / exact - 1).max() < 1e-12
