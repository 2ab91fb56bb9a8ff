"""Observations out as measured (pfault.io.stations, pfault.io.insar): stations report the analytic oedometer
settlement and the P1 interpolant of the written field (by hand here), take the fault side they ask for, agree
at 1 and 2 ranks and continue exactly on a restart; the LOS raster of a uniform settlement w holds u w inside the
land surface and no-data outside, and its rate."""

import csv
import os

import h5py
import numpy as np
import pytest

from conftest import OEDOMETER, TWO_BLOCKS, run_scene

E, NU, DP, H = 10e6, 0.25, 0.1e6, 100.0
C_M = (1 + NU) * (1 - 2 * NU) / (E * (1 - NU))
EXACT = C_M * DP * H                    # settlement of the oedometer's top at t = 10 s (linear in time)
LOS = (0.6, 0.0, 0.8)

OED_STATIONS = "name,x,y,z\ntop,5,5,0\ncorner,10,0,0\nmid,3.3,6.1,-47.3\n"
# two_blocks: a vertical fault x = 1 in a 2 x 1 x 1 box, its plus side x > 1 (it slips 0.21 m in the step)
FAULT_STATIONS = """name,x,y,z,side
# off the fault, one in each block
in_minus,0.37,0.61,-0.29,
in_plus,1.52,0.33,-0.71,
on_fault_minus,1.0,0.43,-0.57,minus
on_fault_plus,1.0,0.43,-0.57,plus
on_fault_default,1.0,0.43,-0.57
"""


def read_station_csv(outdir):
    with open(os.path.join(outdir, "station_displacement.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))
    return rows


def station_series(rows, name):
    """(times, (nt, 3) displacement) of one station from the CSV rows."""
    mine = [r for r in rows if r["name"] == name]
    return (np.array([float(r["time_s"]) for r in mine]),
            np.array([[float(r[k]) for k in ("ux_m", "uy_m", "uz_m")] for r in mine]))


def stations_file(tmp_path, text):
    path = tmp_path / "stations.csv"
    path.write_text(text)
    return str(path)


def p1_values(outdir, x, n_serial):
    """By hand, from fields.h5's last step: {cell of the output mesh containing x: (P1 interpolant there, whether
    the cell is on the plus side of a fault)}: a plus-side cell uses copies of split vertices, numbered after the
    mesh's ``n_serial`` own vertices."""
    with h5py.File(os.path.join(outdir, "fields.h5"), "r") as h5:
        pts, cells = h5["mesh/points"][()], h5["mesh/cells"][()]
        last = sorted(h5["steps"])[-1]
        u = h5["steps"][last]["displacement"][()]
    out = {}
    for c, tet in enumerate(cells):
        v = pts[tet]
        lam = np.linalg.solve((v[1:] - v[0]).T, x - v[0])
        w = np.r_[1 - lam.sum(), lam]
        if w.min() >= -1e-12:
            plus = bool(np.any((tet >= n_serial) & (w > 1e-12)))
            out[c] = (w @ u[tet], plus)
    return out


@pytest.mark.parametrize("ranks", [1, 2])
def test_station_at_the_top_of_the_oedometer_reports_the_analytic_settlement(tmp_path, ranks):
    out = tmp_path / "out"
    _, summary = run_scene(OEDOMETER, out, ranks=ranks, extra=[
        "-pfault_stations", stations_file(tmp_path, OED_STATIONS)])
    assert summary["converged"]
    rows = read_station_csv(out)
    assert list(rows[0]) == ["name", "time_s", "ux_m", "uy_m", "uz_m", "side"]
    t, u = station_series(rows, "top")
    assert np.array_equal(t, np.arange(11.0))                 # time 0 and every step, in s
    assert np.allclose(u[:, 2], -EXACT * t / 10, rtol=0, atol=1e-8 * EXACT)
    assert np.abs(u[:, :2]).max() < 1e-12
    _, corner = station_series(rows, "corner")               # a vertex on the edge of the column
    assert np.allclose(corner[:, 2], -EXACT * t / 10, rtol=0, atol=1e-8 * EXACT)
    _, mid = station_series(rows, "mid")                      # inside: u_z = -c_M dp (z + H) t / 10
    assert np.allclose(mid[:, 2], -C_M * DP * (100 - 47.3) * t / 10, rtol=0, atol=1e-8 * EXACT)
    assert {r["side"] for r in rows} == {""}
    # the HDF5 file holds the same numbers in PyLith's layout of output at points
    with h5py.File(out / "station_displacement.h5", "r") as h5:
        assert [s.decode() for s in h5["stations"][()]] == ["top", "corner", "mid"]
        assert np.array_equal(h5["geometry/vertices"][()], [[5, 5, 0], [10, 0, 0], [3.3, 6.1, -47.3]])
        assert h5["time"].shape == (11, 1, 1) and h5["time"].attrs["units"] == "s"
        assert np.array_equal(h5["time"][:, 0, 0], t)
        disp = h5["vertex_fields/displacement"][()]
        assert disp.shape == (11, 3, 3) and h5["vertex_fields/displacement"].attrs["units"] == "m"
        assert np.array_equal(disp[:, 0], u) and np.array_equal(h5["step"][()], np.arange(11))


def test_stations_report_the_p1_interpolant_and_the_fault_side_they_ask_for(tmp_path):
    out = tmp_path / "out"
    _, summary = run_scene(TWO_BLOCKS, out, extra=["-pfault_stations", stations_file(tmp_path, FAULT_STATIONS)])
    assert summary["converged"] and summary["max_fault_slip_m"] > 0.1
    rows = read_station_csv(out)
    side = {r["name"]: r["side"] for r in rows}
    assert side == {"in_minus": "", "in_plus": "", "on_fault_minus": "minus", "on_fault_plus": "plus",
                    "on_fault_default": "minus"}
    for name, x in (("in_minus", [0.37, 0.61, -0.29]), ("in_plus", [1.52, 0.33, -0.71])):
        hand = p1_values(out, np.array(x), summary["mesh"]["nodes"])
        assert len(hand) == 1                                   # strictly inside one cell
        (value, _), = hand.values()
        _, u = station_series(rows, name)
        assert np.allclose(u[-1], value, rtol=0, atol=1e-12)
        assert np.abs(u[-1]).max() > 1e-3
    on = p1_values(out, np.array([1.0, 0.43, -0.57]), summary["mesh"]["nodes"])    # cells on both sides of the fault
    plus = [v for v, p in on.values() if p]
    minus = [v for v, p in on.values() if not p]
    assert plus and minus
    assert np.allclose(plus, plus[0], atol=1e-12) and np.allclose(minus, minus[0], atol=1e-12)
    _, up = station_series(rows, "on_fault_plus")
    _, um = station_series(rows, "on_fault_minus")
    _, ud = station_series(rows, "on_fault_default")
    assert np.allclose(up[-1], plus[0], rtol=0, atol=1e-12)
    assert np.allclose(um[-1], minus[0], rtol=0, atol=1e-12)
    assert np.array_equal(ud, um)
    assert abs(up[-1, 2] - um[-1, 2]) > 0.1                     # the fault's offset between the two sides
    with h5py.File(out / "station_displacement.h5", "r") as h5:
        assert [s.decode() for s in h5["side"][()]] == ["", "", "minus", "plus", "minus"]


def test_station_files_agree_at_one_and_two_ranks(tmp_path):
    path = stations_file(tmp_path, FAULT_STATIONS)
    runs = {}
    for ranks in (1, 2):
        out = tmp_path / f"out{ranks}"
        _, summary = run_scene(TWO_BLOCKS, out, ranks=ranks, extra=["-pfault_stations", path])
        assert summary["ranks"] == ranks
        runs[ranks] = read_station_csv(out)
    one, two = runs[1], runs[2]
    assert [(r["name"], r["time_s"], r["side"]) for r in one] == [(r["name"], r["time_s"], r["side"]) for r in two]
    a = np.array([[float(r[k]) for k in ("ux_m", "uy_m", "uz_m")] for r in one])
    b = np.array([[float(r[k]) for k in ("ux_m", "uy_m", "uz_m")] for r in two])
    assert np.allclose(a, b, rtol=0, atol=1e-9 * np.abs(a).max())


def read_raster(path):
    import netCDF4
    with netCDF4.Dataset(path) as nc:
        assert nc.Conventions == "CF-1.8"
        for name in ("los_displacement", "los_velocity"):
            assert nc[name].dimensions == ("time", "y", "x")
        assert nc["los_displacement"].units == "m" and nc["los_velocity"].units == "m s-1"
        assert nc["x"].units == "m" and nc["x"].standard_name == "projection_x_coordinate"
        assert nc["time"].units == "s"
        return {k: nc[k][:] for k in ("x", "y", "time", "step", "los_displacement", "los_velocity")}


@pytest.mark.parametrize("ranks", [1, 2])
def test_insar_raster_of_a_uniform_settlement(tmp_path, ranks):
    """The oedometer's top settles uniformly by w(t) = -EXACT t / 10: every pixel inside holds u w; a 3 m
    spacing over the 10 m column puts the last row and column of pixels (centres at 10.5 m) outside."""
    out = tmp_path / "out"
    _, summary = run_scene(OEDOMETER, out, ranks=ranks, extra=[
        "-pfault_insar_los", ",".join(map(str, LOS)), "-pfault_insar_spacing", "3", "-pfault_output_every", "2",
        "-pfault_figures", "true"])
    assert summary["converged"]
    r = read_raster(out / "insar_los.nc")
    assert np.array_equal(r["x"], [1.5, 4.5, 7.5, 10.5]) and np.array_equal(r["y"], [1.5, 4.5, 7.5, 10.5])
    assert np.array_equal(r["time"], [0, 2, 4, 6, 8, 10]) and np.array_equal(r["step"], [0, 2, 4, 6, 8, 10])
    disp, rate = r["los_displacement"], r["los_velocity"]
    inside = np.zeros((4, 4), bool)
    inside[:3, :3] = True
    for k, t in enumerate(r["time"]):
        assert np.array_equal(~np.ma.getmaskarray(disp[k]), inside)         # no-data outside the column
        assert np.allclose(disp[k][inside], LOS[2] * -EXACT * t / 10, rtol=0, atol=1e-9 * EXACT)
        if k == 0:
            assert np.ma.getmaskarray(rate[0]).all()                         # no rate before the first output
        else:
            assert np.array_equal(~np.ma.getmaskarray(rate[k]), inside)
            assert np.allclose(rate[k][inside], LOS[2] * -EXACT / 10, rtol=1e-9)
    assert os.path.getsize(out / "insar_los.png") > 10_000


def test_restart_appends_station_rows_and_raster_times_exactly(tmp_path):
    """A run of 5 of the 10 steps continued to the end equals the uninterrupted run, row for row."""
    obs = ["-pfault_stations", stations_file(tmp_path, OED_STATIONS), "-pfault_insar_los", "0,0,1",
           "-pfault_insar_spacing", "5", "-pfault_output_every", "2"]
    full, part = tmp_path / "full", tmp_path / "part"
    run_scene(OEDOMETER, full, extra=obs)
    run_scene(OEDOMETER, part, extra=[*obs, "-pfault_time_end", "5", "-pfault_time_steps", "5"])
    assert len(read_station_csv(part)) == 3 * 6
    _, s = run_scene(OEDOMETER, part, extra=[*obs, "-pfault_restart", str(part)])
    assert s["restart"]["step"] == 5
    a, b = read_station_csv(full), read_station_csv(part)
    assert [(r["name"], r["time_s"]) for r in a] == [(r["name"], r["time_s"]) for r in b]
    for key in ("ux_m", "uy_m", "uz_m"):
        assert np.allclose([float(r[key]) for r in a], [float(r[key]) for r in b], rtol=0, atol=1e-12)
    with h5py.File(part / "station_displacement.h5", "r") as h5:
        assert np.array_equal(h5["step"][()], np.arange(11))
    ra, rb = read_raster(full / "insar_los.nc"), read_raster(part / "insar_los.nc")
    # outputs every 2 steps and at the last: the first run's step 5 is there, then 6, 8, 10
    assert list(ra["step"]) == [0, 2, 4, 6, 8, 10] and list(rb["step"]) == [0, 2, 4, 5, 6, 8, 10]
    keep = [0, 1, 2, 4, 5, 6]
    assert np.allclose(ra["los_displacement"], rb["los_displacement"][keep], rtol=0, atol=1e-12)


def test_restart_refuses_observations_its_run_did_not_have(tmp_path):
    """Before any solve, one line and exit 1, the run it continues left as it was."""
    part = tmp_path / "part"
    run_scene(OEDOMETER, part, extra=["-pfault_stations", stations_file(tmp_path, OED_STATIONS),
                                      "-pfault_time_end", "5", "-pfault_time_steps", "5"])
    before = {p.name: p.read_bytes() for p in part.iterdir()}
    other = tmp_path / "other.csv"
    other.write_text("name,x,y,z\ntop,5,5,0\n")
    for extra, line in (
            (["-pfault_stations", str(other)],
             f"pfault: error: -pfault_stations: the stations differ from those of the run in -pfault_restart {part}; "
             "give the station file that run had"),
            (["-pfault_stations", stations_file(tmp_path, OED_STATIONS), "-pfault_insar_los", "0,0,1"],
             f"pfault: error: -pfault_insar_los: the run in -pfault_restart {part} has no LOS raster (insar_los.nc); "
             "continue it without -pfault_insar_los, or run the scene from the start with it")):
        proc, _ = run_scene(OEDOMETER, part, extra=[*extra, "-pfault_restart", str(part)], check=False)
        assert proc.returncode == 1 and line in proc.stderr.splitlines(), proc.stderr[-2000:]
        assert "step    6" not in proc.stdout
    assert {p.name: p.read_bytes() for p in part.iterdir()} == before
    assert not [f for f in os.listdir(tmp_path) if ".pfault-" in f]


def test_a_station_file_saved_by_a_spreadsheet(tmp_path):
    """A byte-order mark, semicolons between columns and a decimal comma, capitalised column names, a name with a
    comma, extra columns: read as meant, and the name quoted in the output CSV."""
    path = tmp_path / "stations.csv"
    path.write_bytes('\ufeffName;X;Y;Z;Comment\n"top, north corner";10;9,5;0;benchmark 12\n'.encode("utf-8"))
    out = tmp_path / "out"
    run_scene(OEDOMETER, out, extra=["-pfault_stations", str(path), "-pfault_time_steps", "2"])
    rows = read_station_csv(out)
    assert [r["name"] for r in rows] == ["top, north corner"] * 3
    assert float(rows[-1]["uz_m"]) == pytest.approx(-EXACT, rel=1e-8)
    assert '"top, north corner",10.0,' in (out / "station_displacement.csv").read_text()
    with h5py.File(out / "station_displacement.h5", "r") as h5:
        assert np.array_equal(h5["geometry/vertices"][()], [[10, 9.5, 0]])
