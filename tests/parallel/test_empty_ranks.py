"""Ranks that own nothing: 8 ranks on meshes of 6 and 12 tetrahedra, where some ranks own no cell, no vertex or
no fault face (rank 0 among them in the fault scene), against the same scenes on 1 rank.

Two scenes, each with stations and an InSAR raster: the oedometer column as one hexahedron (6 tetrahedra, no
fault), and a 2 x 1 x 1-cell box (12 tetrahedra) cut by a candidate surface that breaks and slips in its first
step. Every writer runs with ranks that own nothing: the field, fault and land-surface series and the
checkpoint written by every rank (pfault.io.parallel) and gathered to rank 0 (pfault.io.parallel.GATHER_ENV),
the stations, the raster, the restart's read of a checkpoint, the figures; and the solve (assembly, fault faces,
bubbles, the breaking passes). Compared with the 1-rank runs through what does not depend on the partition: every
dataset of fields.h5, fault.h5 and surface.h5 in serial order and the summary maxima (conftest.compare_runs), the
stations' rows, the raster and the checkpoint's datasets. Measured: at most 3e-15 of each dataset's scale (the
oedometer 2.6e-15, the candidate box 7.6e-16, its restart 5.9e-16).
"""

import csv
import os

import h5py
import numpy as np
import pytest

from conftest import OEDOMETER, REPO, compare_runs, mpi_env, run_scene
from pfault.io.insar import read_netcdf
from pfault.post.rundir import read_summary
from pfault.tools.runs import run_captured

RANKS = 8
RTOL = 1e-10
TIMEOUT = 300

# 12 tetrahedra, a candidate surface at x = 200 m: pulled at xmax and drained, one of its two faces breaks and slips
# in step 1 (tensile strength and cohesion 10 kPa)
CANDIDATE_BOX = """# a 2 x 1 x 1-cell box cut at x = 200 m by a candidate surface, pulled and drained
-pfault_scene candidate_box
-pfault_mesh_generator box
-pfault_box_size 400,100,100
-pfault_box_cells 2,1,1
-pfault_box_materials sand
-pfault_box_fault_planes fissure:x:200
-pfault_material_sand_young_modulus 12*MPa
-pfault_material_sand_poisson_ratio 0.30
-pfault_faults fissure
-pfault_fault_fissure_cohesion 10*kPa
-pfault_fault_fissure_tensile_strength 10*kPa
-pfault_fault_fissure_friction_angle 20
-pfault_bc_bottom_type fixed
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type displacement
-pfault_bc_xmax_components x
-pfault_bc_xmax_displacement 1,0,0
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_material_sand_head_drawdown 0:0,10*year:20
-pfault_time_end 10*year
-pfault_time_steps 2
-pfault_solver mumps
"""
BOX_STATIONS = "name,x,y,z,side\nland,50,50,0,\nfault_plus,200,50,-20,plus\nfault_minus,200,50,-20,minus\n" \
               "deep,380,10,-90,\n"
OED_STATIONS = "name,x,y,z\ntop,5,5,0\nmid,3.3,6.1,-47.3\n"
OED = ["-pfault_box_cells", "1,1,1", "-pfault_time_steps", "2", "-pfault_insar_los", "0.6,0,0.8",
       "-pfault_insar_spacing", "2"]
BOX = ["-pfault_insar_los", "0.6,0,0.8", "-pfault_insar_spacing", "25", "-ksp_atol", "0"]


def _run(scene, out, ranks, extra, gathered=False):
    env = mpi_env()
    if gathered:
        env["PFAULT_GATHERED_OUTPUT"] = "1"
    figures = [] if "-pfault_figures" in extra else ["-pfault_figures", "false"]
    args = ["-m", "pfault", scene, "-pfault_output_dir", str(out), *figures, *extra]
    proc = run_captured(args, ranks, cwd=REPO, env=env, timeout=TIMEOUT)
    assert proc.returncode == 0, f"{ranks} ranks: exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The runs, once: {name: output directory}. oed1/oed8: the oedometer as one hexahedron on 1 and 8 ranks
    (written by every rank); box1/box8: the candidate box on 1 and 8 ranks; half1: its first step on 1 rank,
    continued on 8 ranks to the end (cont8, written gathered to rank 0, with the figures)."""
    d = tmp_path_factory.mktemp("empty_ranks")
    (d / "box.opts").write_text(CANDIDATE_BOX)
    (d / "box_stations.csv").write_text(BOX_STATIONS)
    (d / "oed_stations.csv").write_text(OED_STATIONS)
    box, oed = str(d / "box.opts"), OEDOMETER
    oed_obs = [*OED, "-pfault_stations", str(d / "oed_stations.csv")]
    box_obs = [*BOX, "-pfault_stations", str(d / "box_stations.csv")]
    for ranks in (1, RANKS):
        _run(oed, d / f"oed{ranks}", ranks, oed_obs)
        _run(box, d / f"box{ranks}", ranks, box_obs)
    _run(box, d / "half1", 1, [*box_obs, "-pfault_time_end", "5*year", "-pfault_time_steps", "1"])
    proc = _run(box, d / "cont8", RANKS, [*box_obs, "-pfault_restart", str(d / "half1"), "-pfault_figures", "true"],
                gathered=True)
    assert "continuing" in proc.stdout
    return {name: d / name for name in ("oed1", "oed8", "box1", "box8", "half1", "cont8")}


def _stations(path):
    with open(path / "station_displacement.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    keys = [(r["name"], r["time_s"], r["side"]) for r in rows]
    return keys, np.array([[float(r[k]) for k in ("ux_m", "uy_m", "uz_m")] for r in rows])


def _raster(path):
    return read_netcdf(str(path / "insar_los.nc"))


def test_the_meshes_leave_ranks_with_nothing(runs):
    """The premise: on 8 ranks some rank owns no cell, one owns cells but no vertex, and fault faces are on
    two ranks; the fault scene's rank 0 (the one that writes the gathered output) owns nothing."""
    oed = read_summary(runs["oed8"])["partition"]
    assert sum(oed["cells"]) == 6 and oed["cells"].count(0) == 2 and sum(oed["vertices"]) == 8
    box = read_summary(runs["box8"])["partition"]
    assert sum(box["cells"]) == 12 and sum(box["fault_faces"]) == 2 and sum(box["vertices"]) == 12
    assert box["cells"][0] == box["vertices"][0] == box["fault_faces"][0] == 0
    assert any(c > 0 and v == 0 for c, v in zip(box["cells"], box["vertices"]))
    assert sum(f > 0 for f in box["fault_faces"]) == 2
    assert read_summary(runs["box1"])["partition"] == {"cells": [12], "vertices": [12], "fault_faces": [2]}


@pytest.mark.parametrize("scene", ["oed", "box"])
def test_eight_ranks_equal_one(runs, scene):
    """Every output dataset, the summary maxima, the stations and the raster of the 8-rank run are those of the
    1-rank run."""
    one, eight = runs[f"{scene}1"], runs[f"{scene}8"]
    compare_runs(one, eight, RTOL)
    s1, s8 = read_summary(one), read_summary(eight)
    assert s8["ranks"] == RANKS and s8["converged"]
    if scene == "oed":          # the analytic settlement of the column at t = 10 s: c_M alpha |dp| H
        assert s8["max_subsidence_m"] == pytest.approx(0.8333333333, rel=1e-9)
    else:                       # the candidate surface broke and slipped in step 1
        f1, f8 = s1["faults"]["fissure"], s8["faults"]["fissure"]
        assert f8["faces_broken"] == f1["faces_broken"] == 1
        assert f8["first_break_time_s"] == f1["first_break_time_s"] == pytest.approx(5 * 365.25 * 86400)
        assert f8["max_slip_m"] == pytest.approx(f1["max_slip_m"], rel=RTOL) and f1["max_slip_m"] > 0.01
        assert f8["slip_potency_m3"] == pytest.approx(f1["slip_potency_m3"], rel=RTOL)
    k1, u1 = _stations(one)
    k8, u8 = _stations(eight)
    assert k8 == k1 and np.abs(u1).max() > 0.1
    assert np.allclose(u8, u1, rtol=0, atol=RTOL * np.abs(u1).max())
    r1, r8 = _raster(one), _raster(eight)
    for key in ("x", "y", "time", "step"):
        assert np.array_equal(r1[key], r8[key]), key
    for key in ("los_displacement", "los_velocity"):
        a, b = r1[key], r8[key]
        assert np.array_equal(np.isnan(a), np.isnan(b)) and np.isfinite(a).any(), key
        scale = np.nanmax(np.abs(a))
        assert scale > 0 and np.nanmax(np.abs(a - b)) <= RTOL * scale, key


@pytest.mark.parametrize("scene", ["oed", "box"])
def test_checkpoint_written_by_eight_ranks_is_the_one_rank_checkpoint(runs, scene):
    """Every array of checkpoint.h5 is stored in the serial numbering: the 8-rank run's are the 1-rank run's,
    with the same shapes (rows of every vertex, cell and fault face) and attributes but the rank count."""
    with h5py.File(runs[f"{scene}1"] / "checkpoint.h5", "r") as a, \
            h5py.File(runs[f"{scene}8"] / "checkpoint.h5", "r") as b:
        assert {k: v for k, v in a.attrs.items() if k != "ranks"} == \
            {k: v for k, v in b.attrs.items() if k != "ranks"}
        assert a.attrs["ranks"] == 1 and b.attrs["ranks"] == RANKS
        names = []
        a.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        for name in names:
            if name == "steps":             # the step records (their wall times differ)
                continue
            x, y = a[name][()], b[name][()]
            assert x.shape == y.shape and x.dtype == y.dtype, name
            x, y = np.nan_to_num(x), np.nan_to_num(y)     # (an intact face's break time is NaN)
            scale = max(float(np.abs(x).max(initial=0.0)), 1e-300)
            assert float(np.abs(x - y).max(initial=0.0)) <= RTOL * scale, name


def test_restart_on_eight_ranks_gathered_equals_the_uninterrupted_run(runs):
    """The first step on 1 rank, continued on 8 ranks whose output is gathered to an empty rank 0: the
    uninterrupted 1-rank run, with its figures drawn."""
    cont = runs["cont8"]
    s = read_summary(cont)
    assert s["restart"]["step"] == 1 and s["completed_steps"] == [1, 2] and s["ranks"] == RANKS
    compare_runs(runs["box1"], cont, RTOL)
    k1, u1 = _stations(runs["box1"])
    kc, uc = _stations(cont)
    assert kc == k1 and np.allclose(uc, u1, rtol=0, atol=RTOL * np.abs(u1).max())
    r1, rc = _raster(runs["box1"]), _raster(cont)
    assert np.array_equal(r1["step"], rc["step"])
    scale = np.nanmax(np.abs(r1["los_displacement"]))
    assert np.nanmax(np.abs(r1["los_displacement"] - rc["los_displacement"])) <= RTOL * scale
    for png in ("hazard_map.png", "subsidence_map.png", "histories.png", "insar_los.png", "fault_opening_slip.png",
                "fissure_break.png"):
        assert os.path.getsize(cont / png) > 10_000, png
