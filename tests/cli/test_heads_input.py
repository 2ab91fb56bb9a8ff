"""Bad groundwater-model input (-pfault_heads_file), at 1 and 2 ranks: exit code 1, one line naming the file or
option and the fix, printed once, and no output directory. Among them files cut short, a directory given as a file,
and heads that change no cell's pore pressure. A run whose heads leave cells unloaded says how many, and one whose
reference heads are not those of its time 0 warns (both in summary.json)."""

import json
import os

import h5py
import numpy as np
import pytest

from conftest import OEDOMETER
from pfault.tools.mf6_write import write_dis_grb, write_heads
from test_bad_input import _error_lines, run_pfault

COLUMN = """-options_file {oed}
-pfault_time_end 10*day
-pfault_box_cells 1,1,4
"""


def column_model(tmp, ncol=2, times=(0.0, 10.0), nan=False, bottom=-100.0):
    """A one-layer DIS model over the oedometer's 10 m x 10 m column (ncol columns of 10/ncol m), its heads 1 m
    lower at the last saved time than at the others."""
    write_dis_grb(str(tmp / "m.dis.grb"), np.full(ncol, 10.0 / ncol), [10.0], np.zeros((1, ncol)),
                  np.full((1, 1, ncol), bottom))
    heads = np.zeros((len(times), 1, 1, ncol))
    heads[-1] -= 1.0
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
         "coordinates x 2.5..7.5, y 2.5..7.5, z -93.75..-56.25 m; the model spans x 0..10, y 0..10, z -50..0 m); "
         "check what places the mesh in the model: -pfault_mesh_origin (site = mesh + origin), "
         "-pfault_heads_length_unit (the model's length unit in metres, 0.3048 for feet; now 1) and "
         f"-pfault_heads_grid {tmp / 'm.dis.grb'} (the grid file of the model that wrote the heads, whose XORIGIN, "
         "YORIGIN and ANGROT place it), or say what they get: -pfault_heads_outside zero")


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


FIX_CUT = "the copy or the model run that wrote it stopped before the end: copy the file again, or run the model to"


def cut_in_last_record(tmp):
    args = column_model(tmp)
    data = (tmp / "m.hds").read_bytes()
    (tmp / "m.hds").write_bytes(data[:-4])
    return column_scene(tmp, *args), (f"-pfault_heads_file {tmp / 'm.hds'}: cut short: the file is {len(data) - 4:,} "
                                      f"bytes, but its last record (time 10, layer 1) ends at byte {len(data):,}; "
                                      f"{FIX_CUT}")


def cut_grid_file(tmp):
    args = column_model(tmp)
    data = (tmp / "m.dis.grb").read_bytes()
    (tmp / "m.dis.grb").write_bytes(data[:-8])
    return column_scene(tmp, *args), (f"-pfault_heads_grid {tmp / 'm.dis.grb'}: cut short: the file is "
                                      f"{len(data) - 8:,} bytes, its header describes {len(data):,}; {FIX_CUT}")


def heads_directory(tmp):
    args = column_model(tmp)
    (tmp / "run.hds").mkdir()
    return column_scene(tmp, "-pfault_heads_file", str(tmp / "run.hds"), *args[2:]), \
        f"-pfault_heads_file {tmp / 'run.hds'}: is a directory, not a file; give the head file the model saved"


def every_cell_outside_given_zero(tmp):
    """The mesh origin forgotten, and -pfault_heads_outside zero, the fix the line of cells_outside offers: no
    load at all."""
    return column_scene(tmp, *column_model(tmp), "-pfault_mesh_origin", "1000,0,0", "-pfault_heads_outside", "zero"), \
        ("all 24 mesh cells have their centroid outside the groundwater model or in its inactive cells, so "
         "-pfault_heads_outside zero gives none of them a pore-pressure change and the run has no load; check what "
         "places the mesh in the model: -pfault_mesh_origin (site = mesh + origin), -pfault_heads_length_unit (the "
         f"model's length unit in metres, 0.3048 for feet; now 1) and -pfault_heads_grid {tmp / 'm.dis.grb'}")


def one_saved_time(tmp):
    return column_scene(tmp, *column_model(tmp, times=(10.0,))), \
        ("it holds the heads of one saved time (10 days), which are the reference heads h_ref, so dp = rho_w g (h - "
         "h_ref) is zero at every time; give a file with the heads of the times after the reference too")


def heads_without_change(tmp):
    """The heads drop after the run's end (the file's last time, 20 days; the run ends at 10)."""
    return column_scene(tmp, *column_model(tmp, times=(0.0, 10.0, 20.0))), \
        ("the heads at every saved time up to the run's end (10 days) equal the reference heads, those of 0 s, so "
         "there is no pore-pressure change; give the head file of the run whose heads change, or choose the "
         "reference with -pfault_heads_reference_time (a saved time)")


CASES = [grid_mismatch, times_out_of_order, nan_heads, cells_outside, with_tables, with_flow, run_past_the_file,
         grid_file_missing, hdf5_nan]
# cases whose check is a collective one of its own on 2 ranks too (the heads' change is counted over every rank's
# cells; a file's checks run on rank 0 and are shared as the cases above show)
MORE = [(cut_in_last_record, 1), (cut_in_last_record, 2), (cut_grid_file, 1), (heads_directory, 2),
        (every_cell_outside_given_zero, 1), (every_cell_outside_given_zero, 2), (one_saved_time, 1),
        (heads_without_change, 1)]


def _fails_in_one_line(tmp_path, args, message, ranks):
    out = tmp_path / "out"
    code, stdout, stderr = run_pfault([*args, "-pfault_output_dir", str(out)], ranks)
    lines = _error_lines(stderr)
    assert code == 1, stdout[-2000:] + stderr[-3000:]
    assert len(lines) == 1, stderr[-3000:]
    assert lines[0].startswith(("pfault: error: -pfault_heads_file ", "pfault: error: -pfault_heads_grid ")) \
        or "-pfault_time_end" in lines[0], lines[0]
    assert message in lines[0], lines[0]
    assert "Traceback" not in stderr and "Warning" not in stderr, stderr[-3000:]
    assert not os.path.exists(out) and not [p for p in os.listdir(tmp_path) if ".pfault-" in p]   # nor staged


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case", CASES, ids=[c.__name__ for c in CASES])
def test_bad_heads_input(tmp_path, case, ranks):
    _fails_in_one_line(tmp_path, *case(tmp_path), ranks)


@pytest.mark.parametrize("case, ranks", MORE, ids=[f"{c.__name__}-{n}" for c, n in MORE])
def test_heads_cut_short_or_without_change(tmp_path, case, ranks):
    _fails_in_one_line(tmp_path, *case(tmp_path), ranks)


@pytest.mark.parametrize("ranks", [1, 2])
def test_unloaded_cells_and_a_late_reference_are_said(tmp_path, ranks):
    """The column with its lower half below the model, told -pfault_heads_outside zero, heads saved from day 2 (the
    first is the reference): it runs, its upper half settles by c_M rho_w g 1 m 50 m, one line says how many cells
    are unloaded and what share of the volume, one warning names the reference and the option that chooses it, and
    summary.json records both (the same on 1 and 2 ranks)."""
    args = column_scene(tmp_path, *column_model(tmp_path, bottom=-50.0, times=(2.0, 10.0)),
                        "-pfault_heads_outside", "zero", "-pfault_time_steps", "4")
    out = tmp_path / "out"
    code, stdout, stderr = run_pfault([*args, "-pfault_output_dir", str(out), "-pfault_figures", "false"], ranks)
    assert code == 0, stderr[-3000:]
    line = ("pfault: pore-pressure change in 12 of 24 cells (50 % of the volume); none in 12 (50 %), 12 of them "
            "(50 % of the volume) outside the groundwater model (-pfault_heads_outside zero)")
    assert stdout.splitlines().count(line) == 1, stdout
    warning = (f"-pfault_heads_file {tmp_path / 'm.hds'}: the reference heads h_ref are those of its first saved "
               "time, 2 days, not of the run's time 0: drawdown before that time (pumping that started earlier) is "
               "not in the load; if the model was at rest then, say so with -pfault_heads_reference_time 2*day (this "
               "warning then goes), else give heads from before pumping (a steady-state first stress period)")
    assert [ln for ln in stderr.splitlines() if "warning" in ln and "-pfault_box_cells" not in ln] == \
        ["pfault: warning: " + warning], stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["pore_pressure"] == {
        "source": "heads", "cells": 24, "unloaded_cells": 12, "unloaded_volume_fraction": pytest.approx(0.5, rel=1e-12),
        "outside_cells": 12, "outside_volume_fraction": pytest.approx(0.5, rel=1e-12), "reference_time_s": 172800.0,
        "reference_chosen": False, "saved_times": 2, "warnings": [warning]}
    c_m = (1 + 0.25) * (1 - 2 * 0.25) / (10e6 * (1 - 0.25))
    assert summary["max_subsidence_m"] == pytest.approx(c_m * 1000.0 * 9.80665 * 1.0 * 50.0, rel=1e-8)
