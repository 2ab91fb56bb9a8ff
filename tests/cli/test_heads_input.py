"""Bad groundwater-model input (-pfault_heads_file), at 1 and 2 ranks: exit code 1, one line naming the file or
option and the fix, printed once, and no output directory."""

import os

import h5py
import numpy as np
import pytest

from conftest import OEDOMETER
from pfault.io.mf6_write import write_dis_grb, write_heads
from test_bad_input import _error_lines, run_pfault

COLUMN = """-options_file {oed}
-pfault_time_end 10*day
-pfault_box_cells 1,1,4
"""


def column_model(tmp, ncol=2, times=(0.0, 10.0), nan=False, bottom=-100.0):
    """A one-layer DIS model over the oedometer's 10 m x 10 m column (ncol columns of 10/ncol m)."""
    write_dis_grb(str(tmp / "m.dis.grb"), np.full(ncol, 10.0 / ncol), [10.0], np.zeros((1, ncol)),
                  np.full((1, 1, ncol), bottom))
    heads = np.zeros((len(times), 1, 1, ncol))
    if nan:
        heads[-1, 0, 0, 0] = np.nan
    write_heads(str(tmp / "m.hds"), times, heads)
    return ["-pfault_heads_file", str(tmp / "m.hds"), "-pfault_heads_grid", str(tmp / "m.dis.grb")]


def column_scene(tmp, *extra, tables=False):
    text = COLUMN.format(oed=OEDOMETER)
    path = tmp / "column.opts"
    lines = [ln for ln in open(OEDOMETER).read().splitlines()
             if tables or not ln.startswith(("-pfault_material_soil_pressure_change", "-pfault_time_end"))]
    path.write_text("\n".join(lines) + "\n" + "\n".join(text.splitlines()[1:]) + "\n")
    return ["-m", "pfault", str(path), *extra]


def grid_mismatch(tmp):
    args = column_model(tmp)
    write_dis_grb(str(tmp / "other.dis.grb"), np.full(3, 10 / 3), [10.0], np.zeros((1, 3)), np.full((1, 1, 3), -100.0))
    return column_scene(tmp, *args[:2], "-pfault_heads_grid", str(tmp / "other.dis.grb")), \
        "its records are 1 x 2 (rows x columns) in up to 1 layers, but the grid file"


def times_out_of_order(tmp):
    return column_scene(tmp, *column_model(tmp, times=(0.0, 10.0, 5.0))), \
        "its saved times are not increasing (time 5 after 10); give the head file of one run"


def nan_heads(tmp):
    return column_scene(tmp, *column_model(tmp, nan=True)), \
        "1 heads are NaN at time 10; MODFLOW writes dry cells as -1e30 and inactive ones as 1e30"


def cells_outside(tmp):
    return column_scene(tmp, *column_model(tmp, bottom=-50.0)), \
        ("12 of 24 mesh cells have their centroid outside the groundwater model or in its inactive cells (site "
         "coordinates x 2.5..7.5, y 2.5..7.5, z -93.75..-56.25 m); place the mesh with -pfault_mesh_origin, or "
         "say what they get: -pfault_heads_outside zero")


def with_tables(tmp):
    return column_scene(tmp, *column_model(tmp), "-pfault_time_end", "10", tables=True), \
        "the pore pressure comes from these heads; remove the per-material head_drawdown/pressure_change tables"


def with_flow(tmp):
    return column_scene(tmp, *column_model(tmp), "-pfault_flow", "true"), \
        "the pore pressure comes from these heads; remove -pfault_flow (or the head file)"


def run_past_the_file(tmp):
    return column_scene(tmp, *column_model(tmp), "-pfault_time_end", "20*day"), \
        "-pfault_time_end 1.728e+06 s is after the last time saved in"


def grid_file_missing(tmp):
    return column_scene(tmp, column_model(tmp)[0], column_model(tmp)[1]), \
        "a MODFLOW head file needs its binary grid file, -pfault_heads_grid MODEL.dis.grb (or .disv.grb)"


def hdf5_nan(tmp):
    with h5py.File(tmp / "h.h5", "w") as f:
        f["time"] = [0.0, 10.0]
        f["x"], f["y"] = [0.0, 10.0], [0.0, 10.0]
        f["head"] = np.where(np.arange(8).reshape(2, 2, 2) == 5, np.nan, 0.0)
    return column_scene(tmp, "-pfault_heads_file", str(tmp / "h.h5")), \
        "h.h5: 'head' holds 1 NaN or infinite values at time 10; give a value everywhere"


CASES = [grid_mismatch, times_out_of_order, nan_heads, cells_outside, with_tables, with_flow, run_past_the_file,
         grid_file_missing, hdf5_nan]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case", CASES, ids=[c.__name__ for c in CASES])
def test_bad_heads_input(tmp_path, case, ranks):
    args, message = case(tmp_path)
    out = tmp_path / "out"
    code, stdout, stderr = run_pfault([*args, "-pfault_output_dir", str(out)], ranks)
    lines = _error_lines(stderr)
    assert code == 1, stdout[-2000:] + stderr[-3000:]
    assert len(lines) == 1, stderr[-3000:]
    assert lines[0].startswith("pfault: error: -pfault_heads_file ") or "-pfault_time_end" in lines[0], lines[0]
    assert message in lines[0], lines[0]
    assert "Traceback" not in stderr and "Warning" not in stderr, stderr[-3000:]
    assert not os.path.exists(out)


def test_cells_outside_run_with_no_change_when_told(tmp_path):
    """The same column with -pfault_heads_outside zero runs: the cells below the model see no pressure change."""
    args, _ = cells_outside(tmp_path)
    code, _, stderr = run_pfault([*args, "-pfault_heads_outside", "zero", "-pfault_output_dir",
                                  str(tmp_path / "out")], 1)
    assert code == 0, stderr[-3000:]
