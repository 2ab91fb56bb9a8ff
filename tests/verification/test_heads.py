"""Runs whose pore pressure comes from a groundwater model's heads (-pfault_heads_file), at 1 and 2 ranks.

The oedometer column (config/oedometer.opts: 10 m x 10 m x 100 m, rollers on the sides, fixed bottom) under a
MODFLOW model of three layers, the middle one (40 m thick, between node planes of the mesh) losing Dh = 10 m of
head over 10 days: the settlement is c_M rho_w g Dh H_layer (0.326888333 m), reached by P1 to 1e-8 at every step,
through a DIS grid, a rotated DISV grid and the generic HDF5 layout. The example site (config/site_example) gives
the same answer on 1 and 2 ranks.
"""

import numpy as np
import pytest

from conftest import OEDOMETER, compare_runs, run_scene
from pfault.tools.mf6_write import write_dis_grb, write_disv_grb, write_heads

E, NU = 10e6, 0.25
C_M = (1 + NU) * (1 - 2 * NU) / (E * (1 - NU))
RHO_G = 1000.0 * 9.80665
DH, H_LAYER = 10.0, 40.0
EXACT = C_M * RHO_G * DH * H_LAYER
ORIGIN = (5000.0, 7000.0, 20.0)             # site coordinates of the mesh's origin
BOTTOMS = (-10.0, -50.0, -80.0)             # site elevations: the mesh spans z = 20 - 100 .. 20
SITE = "config/site_example/site.opts"


def test_analytic_value():
    assert EXACT == pytest.approx(0.326888333, rel=1e-8)


def column_heads(times=(0.0, 10.0)):
    """Heads (ntimes, 3 layers): 15 m everywhere, the middle layer 10 m lower at the last time, linear."""
    h = np.full((len(times), 3), 15.0)
    h[:, 1] -= DH * np.asarray(times) / times[-1]
    return h


def dis_files(tmp_path):
    top, botm = np.full((2, 2), 20.0), np.stack([np.full((2, 2), b) for b in BOTTOMS])
    write_dis_grb(str(tmp_path / "col.dis.grb"), [5.0, 5.0], [5.0, 5.0], top, botm, xorigin=ORIGIN[0],
                  yorigin=ORIGIN[1])
    write_heads(str(tmp_path / "col.hds"), [0.0, 10.0], np.broadcast_to(column_heads()[:, :, None, None],
                                                                         (2, 3, 2, 2)))
    return ["-pfault_heads_file", str(tmp_path / "col.hds"), "-pfault_heads_grid", str(tmp_path / "col.dis.grb")]


def disv_files(tmp_path):
    """Two triangles and a quadrilateral over (-10..20) x (-10..20) m, rotated 35 degrees about the column's centre."""
    verts = np.array([[-10, -10], [20, -10], [20, 5], [-10, 20], [20, 20]], float)
    cells = [[0, 3, 2], [0, 2, 1], [3, 4, 2]]
    centre = np.array([ORIGIN[0] + 5.0, ORIGIN[1] + 5.0])
    a = np.deg2rad(35.0)
    # the grid's local point (5, 5) sits on the column's centre
    origin = centre - np.array([5 * np.cos(a) - 5 * np.sin(a), 5 * np.sin(a) + 5 * np.cos(a)])
    write_disv_grb(str(tmp_path / "col.disv.grb"), verts, cells, np.full(3, 20.0),
                   np.stack([np.full(3, b) for b in BOTTOMS]), xorigin=origin[0], yorigin=origin[1], angrot=35.0)
    write_heads(str(tmp_path / "colv.hds"), [0.0, 10.0], np.broadcast_to(column_heads()[:, :, None], (2, 3, 3)))
    return ["-pfault_heads_file", str(tmp_path / "colv.hds"), "-pfault_heads_grid", str(tmp_path / "col.disv.grb")]


def hdf5_file(tmp_path):
    """Heads on a regular grid of nodes in x, y, z: the middle layer's drop on node pairs 2e-9 m apart at its
    bounds (-50, -10: node planes of the mesh), so that the multilinear interpolant is the layer's value at every
    cell centroid."""
    import h5py
    z = np.array([-80.0, -50.0 - 1e-9, -50.0 + 1e-9, -10.0 - 1e-9, -10.0 + 1e-9, 20.0])
    drop = np.array([0.0, 0.0, 1.0, 1.0, 0.0, 0.0])
    with h5py.File(tmp_path / "col.h5", "w") as f:
        f["time"] = np.array([0.0, 10.0])
        f["time"].attrs["units"] = "day"
        f["x"], f["y"], f["z"] = np.array([4990.0, 5020.0]), np.array([6990.0, 7020.0]), z
        f["head"] = np.stack([np.broadcast_to((15.0 - DH * s * drop)[:, None, None], (6, 2, 2)) for s in (0.0, 1.0)])
    return ["-pfault_heads_file", str(tmp_path / "col.h5")]


def column(tmp_path, files, ranks=1):
    extra = ["-pfault_box_cells", "2,2,10", "-pfault_time_end", "10*day", "-pfault_mesh_origin",
             ",".join(str(v) for v in ORIGIN), *files]
    opts = tmp_path / "column.opts"
    opts.write_text("\n".join(ln for ln in open(OEDOMETER).read().splitlines()
                              if not ln.startswith(("-pfault_material_soil_pressure_change", "-pfault_time_end"))))
    return run_scene(str(opts), tmp_path / f"out{ranks}", ranks=ranks, extra=extra)


def assert_column(summary):
    assert summary["converged"]
    subs = np.array([s["max_subsidence_m"] for s in summary["steps"]])
    assert np.allclose(subs, EXACT * np.arange(1, 11) / 10, rtol=1e-8)
    assert abs(summary["max_subsidence_m"] - EXACT) / EXACT < 1e-8
    assert summary["max_horizontal_displacement_m"] < 1e-10


@pytest.mark.parametrize("ranks", [1, 2])
def test_oedometer_settlement_through_modflow_dis_heads(tmp_path, ranks):
    proc, summary = column(tmp_path, dis_files(tmp_path), ranks=ranks)
    assert "groundwater-model heads" in proc.stdout and summary["ranks"] == ranks
    assert_column(summary)


def test_oedometer_settlement_through_modflow_disv_heads(tmp_path):
    _, summary = column(tmp_path, disv_files(tmp_path))
    assert_column(summary)


def test_oedometer_settlement_through_the_generic_hdf5_layout(tmp_path):
    _, summary = column(tmp_path, hdf5_file(tmp_path))
    assert_column(summary)


def test_site_example_agrees_on_one_and_two_ranks(tmp_path):
    _, one = run_scene(SITE, tmp_path / "one", ranks=1)
    _, two = run_scene(SITE, tmp_path / "two", ranks=2)
    assert one["converged"] and two["converged"] and one["max_subsidence_m"] > 1.0
    assert compare_runs(tmp_path / "one", tmp_path / "two", 1e-10) < 1e-10
