"""Figures of fissures that formed (pfault.post.fissures): the break map of each fault with broken faces and the
traces on the hazard map of the fissures that reached the land surface.

The run directory is a real one (the fissure box, config/hard/fissure_box.opts, 2 steps on 1 rank: a vertical
fault x = 375 m, 0 <= y <= 100 m, from the land surface z = 0 down to z = -40 m in rows of 10 m) into whose
fault.h5 the test writes a fissure's history in the layout a run with a tensile strength writes (``broken`` and
``break_time`` per face in each step group, listed in fault.xdmf; summary.json's per-fault figures): at the first
step (5 years) the faces between 10 and 20 m deep break, the fissure starting below the land surface; at the second
(10 years) those between the surface and 10 m deep, and the fissure reaches the land surface along the fault's
whole width.
"""

import json
import shutil

import numpy as np
import pytest

from conftest import FISSURE_BOX, run_scene
from pfault.io.output import open_h5, step_entry, write_xdmf
from pfault.post import figures, fissures, margin_map, plots, rundir

YEAR = 365.25 * 86400.0
PNG = b"\x89PNG\r\n\x1a\n"


def _write_history(run_dir):
    """``broken`` and ``break_time`` in every step of fault.h5 (the history above), fault.xdmf listing them, and
    summary.json's figures of the fissure at the end; returns the times of the steps (s)."""
    with open_h5(str(run_dir / "fault.h5"), "r+") as f:
        pts, cells = f["mesh/points"][...], f["mesh/cells"][...]
        zc = pts[cells, 2].mean(axis=1)
        rows = [(zc < -10.0) & (zc > -20.0), zc > -10.0]       # in the order they break
        groups = [f["steps"][k] for k in sorted(f["steps"])]
        times = [float(g.attrs["time"]) for g in groups]
        entries = []
        for i, g in enumerate(groups):
            broken = np.zeros(len(cells), dtype=np.int64)
            when = np.full(len(cells), np.nan)
            for j, row in enumerate(rows[:i]):
                broken[row], when[row] = 1, times[j + 1]
            for name, value in (("broken", broken), ("break_time", when)):
                if name in g:
                    del g[name]
                g.create_dataset(name, data=value).attrs["center"] = "Cell"
            entries.append(step_entry(g))
        mesh = ((pts.shape, pts.dtype), (cells.shape, cells.dtype))
    write_xdmf(str(run_dir), "fault", mesh, entries)
    summary = json.loads((run_dir / "summary.json").read_text())
    summary["faults"]["fissure"].update(broken_area_m2=2000.0, broken_depth_m=20.0, broken_length_m=100.0,
                                        first_break_time_s=times[1])
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return times


@pytest.fixture(scope="module")
def box_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("fissures") / "box"
    run_scene(FISSURE_BOX, run_dir, extra=["-pfault_time_steps", "2"])
    return run_dir


def test_a_run_without_breaking_draws_as_before(box_run):
    """A pre-existing fault (every face broken from the start, no break time): no fissure formed, no fissure figure,
    no trace on the hazard map, the four figures as before and the fault's margins to failure."""
    b = fissures.read_breaks(str(box_run))
    assert b is not None and len(b.broken) > 0 and not b.broken.any()
    assert fissures.fissure_figure(str(box_run)) is None
    paths = figures.make_figures(str(box_run))
    assert sorted(p.rsplit("/", 1)[-1] for p in paths) == sorted(figures.FIGURES + (margin_map.FIGURE,))
    assert not (box_run / fissures.FIGURE).exists()


def test_fissure_history_measured_and_drawn(box_run, tmp_path):
    """The fissure's extent at each output time, from the faces: buried at 5 years (1,000 m^2, 20 m deep, no
    surface trace), at the land surface at 10 years (2,000 m^2, 20 m deep, a 100 m trace at x = 375 m since 10
    years); the figures: fissure_break.png and the hazard map with the trace."""
    run_dir = tmp_path / "box"
    shutil.copytree(box_run, run_dir)
    t = _write_history(run_dir)
    assert len(t) == 3 and t[1] == pytest.approx(5 * YEAR) and t[2] == pytest.approx(10 * YEAR)
    # fault.xdmf lists the new datasets, as a run that writes them does
    assert rundir.read_fault(str(run_dir)).cell_data["broken"].sum() == 32

    first = fissures.read_breaks(str(run_dir), step=1)
    m = fissures.measures(str(run_dir), first)["fissure"]      # not the last output time: not summary.json's
    assert m["broken_area_m2"] == pytest.approx(1000.0, rel=1e-12)
    assert m["broken_depth_m"] == pytest.approx(20.0, rel=1e-12)
    assert m["broken_length_m"] == 0.0 and np.isnan(m["surface_break_time_s"])
    assert m["first_break_time_s"] == t[1]

    last = fissures.read_breaks(str(run_dir))
    on_top = fissures.on_land_surface(str(run_dir), last.points)
    assert np.array_equal(on_top, np.abs(last.points[:, 2]) < 1e-9)    # surface.h5's points: the plane z = 0
    m = fissures.fissure_measures(last, on_top, ["fissure"])["fissure"]
    assert m["broken_area_m2"] == pytest.approx(2000.0, rel=1e-12)
    assert m["broken_depth_m"] == pytest.approx(20.0, rel=1e-12)
    assert m["broken_length_m"] == pytest.approx(100.0, rel=1e-12)
    assert (m["first_break_time_s"], m["surface_break_time_s"]) == (t[1], t[2])
    assert m["max_opening_m"] == pytest.approx(np.max(rundir.read_fault(str(run_dir)).cell_data["opening"][
        last.broken]), rel=1e-12)
    assert fissures.measures(str(run_dir), last)["fissure"] == pytest.approx(m, rel=1e-12, nan_ok=True)
    edges, face = fissures.surface_edges(last.faces, last.broken, on_top)
    assert len(edges) == 8 and np.all(last.broken[face])
    assert np.allclose(last.points[edges][:, :, [0, 2]], [375.0, 0.0])
    h = fissures.history(str(run_dir))["fissure"]
    assert np.array_equal(h["time_s"], t)
    assert h["broken_area_m2"] == pytest.approx([0.0, 1000.0, 2000.0], rel=1e-12)
    assert h["broken_depth_m"] == pytest.approx([0.0, 20.0, 20.0], rel=1e-12)
    assert h["broken_length_m"] == pytest.approx([0.0, 0.0, 100.0], rel=1e-12)
    assert list(fissures.history(str(run_dir), 1)["fissure"]["time_s"]) == t[:2]
    # the same time by its value, as the hazard map asks for it
    assert fissures.read_breaks(str(run_dir), time=t[1]).index == 1

    paths = figures.make_figures(str(run_dir))
    assert str(run_dir / fissures.FIGURE) in paths
    for name in (fissures.FIGURE, "hazard_map.png"):
        assert (run_dir / name).read_bytes()[:8] == PNG, name

    plt = plots.pyplot()
    fig, ax = plt.subplots()
    assert fissures.draw_surface_traces(ax, str(run_dir), t[2], 1e-3) == pytest.approx(100.0, rel=1e-12)
    assert fissures.draw_surface_traces(ax, str(run_dir), t[1], 1e-3) == 0.0
    plt.close(fig)
