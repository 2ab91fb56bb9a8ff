"""Small versions of the two case studies (Franceschini et al., Proc. IAHS 372, 2015): physical invariants and
1-vs-2 rank agreement. Paper-size runs and the comparison with the paper are a benchmark
(benchmarks/case_studies.py), not a test.

Each scene runs once per rank count at mesh size factor 4 with 3 time steps of 3.3 years (conftest.shared_run:
tests/verification/test_faces_hold.py checks the same runs): about 10 s per run on the 2-core reference machine,
four runs in all.

Sign conventions (pfault.mesh.fault): the vertex order of a fault triangle in fault.xdmf gives its normal,
from the minus to the plus side; jumps are plus minus minus. fields.xdmf holds the serial vertices (used by
the minus-side cells) followed by the copies of the split fault vertices (used by the plus-side cells), so the
tetrahedron that has a fault triangle's own three vertex ids as a face is its minus-side cell.
"""

import json
import os

import numpy as np
import pytest

from conftest import QUERETARO, WUXI
from pfault.post import meshes, rundir

SMALL = ("-pfault_mesh_size_factor", "4", "-pfault_time_steps", "3")
WUXI_CREST_X = 1000.0
QRO_FAULT_X = 10000.0
QRO_WELLS = np.array([[12000.0, 12000.0], [12000.0, 15000.0], [12000.0, 18000.0]])
# 1-vs-2 rank agreement of the summary maxima. The mechanics is solved with LU (MUMPS) and Newton to
# snes_rtol 1e-10, the groundwater flow with CG + AMG to ksp_rtol 1e-10 (whose iterates depend on the
# partition): observed differences are ~1e-15 at Wuxi (direct solves only) and ~6e-11 at Queretaro (the
# flow's iterative tolerance); 1e-8 leaves two orders of magnitude of margin above that and still catches
# any real partition dependence (a face counted twice or missed changes the maxima by far more).
RANK_RTOL = 1e-8


def _run(shared_run, scene):
    out = {}
    for ranks in (1, 2):
        summary, outdir = shared_run(scene, ranks, SMALL)
        assert summary is not None and summary["converged"], f"{scene} on {ranks} rank(s) did not converge"
        out[ranks] = (str(outdir), summary)
    return out


@pytest.fixture(scope="module")
def wuxi(shared_run):
    return _run(shared_run, WUXI)


@pytest.fixture(scope="module")
def queretaro(shared_run):
    return _run(shared_run, QUERETARO)


def _surface_subsidence(run_dir):
    f = rundir.read_fields(run_dir)
    top = np.unique(meshes.top_surface(f.points, f.cells))
    return f.points[top], -f.point_data["displacement"][top, 2], f


def _minus_cells(fields, fault):
    """Index of the minus-side tetrahedron of every fault triangle (see the module docstring)."""
    n = len(fields.points)
    faces = np.sort(fields.cells[:, meshes.TET_FACES].reshape(-1, 3), axis=1)
    keys = (faces[:, 0] * n + faces[:, 1]) * n + faces[:, 2]
    tri = np.sort(fault.cells, axis=1)
    want = (tri[:, 0] * n + tri[:, 1]) * n + tri[:, 2]
    order = np.argsort(keys)
    pos = np.searchsorted(keys[order], want)
    pos = np.minimum(pos, len(keys) - 1)
    found = keys[order][pos] == want
    assert found.all(), "every fault triangle is a face of its minus-side cell"
    # a triangle whose vertices are all split is a face of exactly one cell with the original ids
    assert np.all(np.searchsorted(keys[order], want, side="right") - np.searchsorted(keys[order], want) == 1)
    return order[pos] // 4


# ------------------------------------------------------------------------------------------------------
# Wuxi: the fissure opens above the bedrock ridge
# ------------------------------------------------------------------------------------------------------
def test_wuxi_subsidence_follows_bedrock_depth(wuxi):
    run_dir, summary = wuxi[2]
    pts, sub, _ = _surface_subsidence(run_dir)
    assert np.all(sub > 0.0), "the whole land surface subsides"
    d = np.abs(pts[:, 0] - WUXI_CREST_X)
    crest, far = sub[d < 50.0], sub[d > 600.0]       # cover 5 m thick at the crest, 100 m beyond the flanks
    assert len(crest) and len(far)
    assert far.mean() > 5.0 * crest.mean(), (crest.mean(), far.mean())
    imax = int(np.argmax(sub))
    assert d[imax] > 500.0, "the largest subsidence lies where the compressible cover is thickest"
    assert sub[imax] == pytest.approx(summary["max_subsidence_m"], rel=1e-12)


def test_wuxi_fissure_opens_near_the_surface(wuxi):
    run_dir, summary = wuxi[2]
    fault = rundir.read_fault(run_dir)
    opening = fault.cell_data["opening"]
    _, area, cen = meshes.face_geometry(fault.points, fault.cells)
    assert summary["max_fault_opening_m"] > 0.0
    # the reported opening is the open faces' (a closed face's jump is the discretisation's)
    assert opening[fault.cell_data["state"] == 2].max() == pytest.approx(summary["max_fault_opening_m"], rel=1e-12)
    assert area[opening > 1e-4].sum() > 0.5 * area.sum(), "most of the fissure has opened after 10 years"
    # the fissure spans the ground surface down to the crest (5 m): the opening is largest at the surface and
    # vanishes at the (unsplit) crest line, so the opening-weighted depth lies in its upper half
    ztop, zbot = fault.points[fault.cells, 2].max(), fault.points[fault.cells, 2].min()
    w = np.clip(opening, 0.0, None) * area
    assert (w * cen[:, 2]).sum() / w.sum() > 0.5 * (ztop + zbot)
    f = rundir.read_fields(run_dir)
    surf_open, _ = meshes.surface_fault_jumps(f, fault)
    assert surf_open >= opening.max(), "the nodal opening at the surface bounds the face averages"


def test_wuxi_fissure_prone_length_is_the_fissure_trace(wuxi):
    """The strained band runs along the fissure's 5 km trace on both of its sides (the open fissure splits the
    land surface there): one stretch of land surface, counted once. Measured at size factor 4: 5001.2 m, the band's
    extent along its mean fissure direction (10,000 m when the sides were counted apart)."""
    run_dir, summary = wuxi[2]
    assert summary["max_fissure_prone_length_m"] == pytest.approx(5000.0, rel=2e-3)
    surf = rundir.read_surface(run_dir)
    prone = surf.cell_data["horizontal_strain"] > summary["hazard_strain_threshold"]
    x = surf.points[surf.cells[prone]][:, :, 0]
    assert (x.min() < WUXI_CREST_X - 1.0) and (x.max() > WUXI_CREST_X + 1.0)    # on both sides of the trace


def test_wuxi_slip_much_smaller_than_opening(wuxi):
    _, summary = wuxi[2]
    assert summary["max_fault_slip_m"] < 0.25 * summary["max_fault_opening_m"]


# ------------------------------------------------------------------------------------------------------
# Queretaro: the fault slides, the sediment side goes down
# ------------------------------------------------------------------------------------------------------
def test_queretaro_subsidence_on_sediment_side_near_wells(queretaro):
    run_dir, summary = queretaro[2]
    pts, sub, _ = _surface_subsidence(run_dir)
    imax = int(np.argmax(sub))
    assert sub[imax] == pytest.approx(summary["max_subsidence_m"], rel=1e-12)
    assert pts[imax, 0] > QRO_FAULT_X, "largest subsidence on the sediment side"
    dist = np.min(np.linalg.norm(pts[imax, None, :2] - QRO_WELLS[None], axis=2))
    assert dist < 2500.0, f"largest subsidence {dist:.0f} m from the nearest well"
    near = (pts[:, 0] > QRO_FAULT_X) & (np.min(np.linalg.norm(pts[:, None, :2] - QRO_WELLS[None], axis=2), axis=1)
                                        < 5000.0)
    assert np.all(sub[near] > 0.0), "the sediments around the wells subside"
    rock = pts[:, 0] < QRO_FAULT_X - 1.0
    assert np.max(np.abs(sub[rock])) < 0.05 * sub[imax], "the rock side barely moves"


def test_queretaro_sediment_side_slides_down(queretaro):
    run_dir, summary = queretaro[2]
    fields, fault = rundir.read_fields(run_dir), rundir.read_fault(run_dir)
    normals, area, cen = meshes.face_geometry(fault.points, fault.cells)
    # which side is which: the minus cell of each face is rock and lies behind the normal
    minus = _minus_cells(fields, fault)
    names = rundir.read_materials(run_dir)
    assert {names[int(m)] for m in np.unique(fields.cell_data["material"][minus])} == {"rock"}
    behind = np.einsum("ij,ij->i", fields.points[fields.cells[minus]].mean(axis=1) - cen, normals)
    assert np.all(behind < 0.0), "the normal points from the minus (rock) to the plus (sediment) side"
    # the plus (sediment) side moves down relative to the rock: negative dip slip where the fault slides
    slip = fault.cell_data["slip"]
    mag = np.linalg.norm(slip, axis=1)
    # the reported slip is that of the faces that have slid (a stuck face's jump is the discretisation's)
    assert mag[fault.cell_data["slid"] == 1].max() == pytest.approx(summary["max_fault_slip_m"], rel=1e-12)
    dip = meshes.dip_slip(slip, normals)
    big = mag > 0.25 * mag.max()
    assert big.any()
    assert np.all(dip[big] < 0.0)
    assert np.all(np.abs(dip[big]) > 0.8 * mag[big]), "mainly dip slip"
    assert summary["max_fault_slip_m"] > 3.0 * summary["max_fault_opening_m"], "the fault mainly slides"


def test_queretaro_drawdown_largest_at_wells(queretaro):
    run_dir, summary = queretaro[2]
    f = rundir.read_fields(run_dir)
    dd = -f.point_data["head_change"]
    imax = int(np.argmax(dd))
    last = [s for s in summary["steps"] if "max_drawdown_m" in s][-1]
    assert dd[imax] == pytest.approx(last["max_drawdown_m"], rel=1e-12)
    dist = np.min(np.linalg.norm(f.points[imax, :2] - QRO_WELLS, axis=1))
    assert dist < 200.0, f"largest drawdown {dist:.0f} m from a well (element size there ~160 m)"
    assert f.points[imax, 2] <= -20.0 + 1e-9, "in the aquifer (z <= -20 m)"
    steps = [s["max_drawdown_m"] for s in summary["steps"] if "max_drawdown_m" in s]
    assert np.all(np.diff(steps) > 0.0), "the drawdown grows with the pumping rate"


# ------------------------------------------------------------------------------------------------------
# 1 vs 2 ranks
# ------------------------------------------------------------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("scene", ["wuxi", "queretaro"])
def test_one_vs_two_ranks(scene, request):
    runs = request.getfixturevalue(scene)
    (_, s1), (_, s2) = runs[1], runs[2]
    assert (s1["ranks"], s2["ranks"]) == (1, 2)
    assert s1["mesh"] == s2["mesh"]
    for key in ("max_subsidence_m", "max_horizontal_displacement_m", "max_fault_opening_m", "max_fault_slip_m"):
        assert s2[key] == pytest.approx(s1[key], rel=RANK_RTOL, abs=1e-14), key
    for a, b in zip(s1["steps"], s2["steps"]):
        for key in ("max_subsidence_m", "max_fault_opening_m", "max_fault_slip_m", "max_drawdown_m"):
            if key in a:
                assert b[key] == pytest.approx(a[key], rel=RANK_RTOL, abs=1e-14), (key, a["time_s"])
        # a face at a switch (zero effective traction, no jump: open, slipping and stuck at once) lands on either
        # side within the Newton tolerance, which the partition moves: the counts agree to a few faces
        nf = s1["mesh"]["fault_faces"]
        for key in ("stick", "slip", "open"):
            if key in a:
                assert abs(a[key] - b[key]) <= max(2, 0.005 * nf), (key, a["time_s"], a[key], b[key])
