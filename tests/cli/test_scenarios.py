"""python -m pfault.scenarios: plans of a small drained box compared in one table.

The box is linear (elastic skeleton, linear flow, no fault): halving the pumping halves every displacement, so
the halved plan's subsidence and strain are half the baseline's to round-off and the no-pumping plan's are zero.
With soils that remember (config/seasonal_plans.opts on config/seasonal.opts, one column of cells) plans differ in
kind: the plan that holds the heads above the critical heads compacts nothing inelastically and recovers every
winter, halving the drawdown leaves about 0.37 of the subsidence, not 0.5, and what stays after the pumping stops is
the inelastic part.
The table (scenarios.csv) holds each plan's own summary.json values exactly; a plan that fails is a row with its
exit code and error line while the others complete; a bad plans file is one line, exit 1, nothing written.
"""

import csv
import json
import os

import pytest

from conftest import FLOW_BOX, run

TIMEOUT = 300
# the flow box (conftest) for a day in two steps
BOX = FLOW_BOX + "-pfault_time_end 1*day\n-pfault_time_steps 2\n"
PLANS = """# every plan: the well screen as in the scene (a common option)
-pfault_flow_well_screen -1,-15
[halved]
-pfault_flow_well_rate 0:0,1*day:1.5*L/s
[no_pumping]
-pfault_flow_well_rate 0:0,1*day:0
"""


def scenarios(tmp_path, plans, *extra, scene=None):
    scene_path = tmp_path / "box.opts"
    scene_path.write_text(scene or BOX)
    plans_path = tmp_path / "plans.opts"
    plans_path.write_text(plans)
    out = tmp_path / "out"
    proc = run(["-m", "pfault.scenarios", str(scene_path), str(plans_path), "--output", str(out),
                *extra], timeout=TIMEOUT, check=False)
    return proc, out


def table(out):
    with open(out / "scenarios.csv", newline="") as fh:
        return {r["plan"]: r for r in csv.DictReader(fh)}


def summary(out, plan):
    with open(out / plan / "summary.json") as fh:
        return json.load(fh)


KEYS = ("max_subsidence_m", "final_subsidence_m", "max_fault_opening_m", "max_fault_slip_m",
        "max_horizontal_strain", "max_angular_distortion", "max_fissure_prone_length_m")
SOIL_KEYS = ("max_subsidence_inelastic_m", "min_head_margin_m")


@pytest.fixture(scope="module")
def box_plans(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("scenarios")
    proc, out = scenarios(tmp, PLANS + "[broken]\n-pfault_time_steps 0\n", "--workers", "2")
    return proc, out


def test_plans_are_ordered_as_the_physics_says(box_plans):
    proc, out = box_plans
    rows = table(out)
    assert list(rows) == ["baseline", "halved", "no_pumping", "broken"]
    base, half, none = (float(rows[p]["max_subsidence_m"]) for p in ("baseline", "halved", "no_pumping"))
    assert base > 0.05
    assert half == pytest.approx(0.5 * base, rel=1e-10)
    assert abs(none) <= 1e-12 * base
    assert float(rows["halved"]["max_horizontal_strain"]) == pytest.approx(
        0.5 * float(rows["baseline"]["max_horizontal_strain"]), rel=1e-10)
    assert float(rows["no_pumping"]["max_fissure_prone_length_m"]) == 0.0
    assert rows["halved"]["options"] == "-pfault_flow_well_rate 0:0,1*day:1.5*L/s"
    assert (out / "scenarios.png").exists()
    assert "halved" in proc.stdout and "no_pumping" in proc.stdout
    # linear soils: the soils' columns are empty in the file and left out of the printed table
    assert all(rows[p][k] == "" for p in rows for k in SOIL_KEYS) and "head margin" not in proc.stdout


def test_the_table_holds_each_plans_own_summary_values(box_plans):
    _, out = box_plans
    rows = table(out)
    for plan in ("baseline", "halved", "no_pumping"):
        s = summary(out, plan)
        assert rows[plan]["status"] == "completed" and rows[plan]["exit_code"] == "0"
        for key in KEYS:
            assert float(rows[plan][key]) == s[key], (plan, key)


def test_a_failed_plan_is_reported_and_the_others_complete(box_plans):
    proc, out = box_plans
    assert proc.returncode == 8, proc.stderr
    row = table(out)["broken"]
    assert row["status"] == "failed" and row["exit_code"] == "1"
    assert row["error"] == "pfault: error: -pfault_time_steps: need at least one step"
    assert all(row[k] == "" for k in KEYS)
    assert "broken: pfault: error: -pfault_time_steps" in proc.stdout
    assert os.path.exists(out / "broken.log")
    assert not os.path.exists(out / "broken")


def test_plans_on_soils_that_remember_differ_in_kind_not_by_a_factor(tmp_path):
    """config/seasonal_plans.opts on one column of the seasonal scene, a step every half year (its summer lows and
    winter highs): the sand preconsolidated 4 m below the initial heads, the clay 2 m."""
    out = tmp_path / "out"
    proc = run(["-m", "pfault.scenarios", "config/seasonal.opts", "config/seasonal_plans.opts", "--output", str(out),
                "--workers", "2", "-pfault_box_cells", "1,1,40", "-pfault_time_steps", "16", "-pfault_output_every",
                "16"], timeout=TIMEOUT, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = {plan: {k: float(v) for k, v in r.items() if k in KEYS + SOIL_KEYS} for plan, r in table(out).items()}
    assert list(rows) == ["baseline", "held", "halved", "stopped_year4"]
    base, held, half, stopped = (rows[p] for p in rows)
    # held above the critical heads (the clay's lowest head -1.5 m against -2 m, the sand's -3 m against -4 m):
    # nothing inelastic, the least margin the clay's 0.5 m, and the summer's 34 mm recovered by the last winter
    assert held["max_subsidence_inelastic_m"] == 0.0
    assert held["min_head_margin_m"] == pytest.approx(0.5, abs=1e-9)
    assert held["max_subsidence_m"] == pytest.approx(0.03399, rel=2e-3) and abs(held["final_subsidence_m"]) < 1e-9
    # below them: cells on the virgin line (margin 0 up to round-off), most of the subsidence inelastic
    for plan in (base, half, stopped):
        assert abs(plan["min_head_margin_m"]) < 1e-9 and plan["max_subsidence_inelastic_m"] > 0.15
    assert base["max_subsidence_m"] == pytest.approx(0.7052, rel=2e-3)
    assert base["max_subsidence_inelastic_m"] == pytest.approx(0.5864, rel=2e-3)
    # half the drawdown, not half the subsidence: the first 2 m (clay) and 4 m (sand) are elastic in both plans
    ratio = half["max_subsidence_m"] / base["max_subsidence_m"]
    assert ratio == pytest.approx(0.3734, rel=2e-3) and ratio < 0.5 - 0.1
    # pumping stopped: the heads recover, the elastic part comes back, the inelastic part stays
    assert stopped["final_subsidence_m"] == pytest.approx(0.2507, rel=2e-3)
    assert stopped["final_subsidence_m"] == pytest.approx(stopped["max_subsidence_inelastic_m"], rel=0.05)
    assert stopped["final_subsidence_m"] < 0.75 * stopped["max_subsidence_m"]
    for plan in rows:                                       # the table holds each plan's own summary.json values
        s = summary(out, plan)
        assert rows[plan]["min_head_margin_m"] == s["min_head_margin_m"]
        assert rows[plan]["max_subsidence_inelastic_m"] == s["max_subsidence_inelastic_m"]
    assert "inelastic subs. [m]" in proc.stdout and "head margin [m]" in proc.stdout


def test_two_ranks_per_plan_agree_with_one(box_plans, tmp_path):
    _, out1 = box_plans
    proc, out2 = scenarios(tmp_path, PLANS, "--ranks", "2", "--workers", "1")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    one, two = table(out1), table(out2)
    assert summary(out2, "halved")["ranks"] == 2
    for plan in ("baseline", "halved"):
        for key in ("max_subsidence_m", "max_horizontal_strain", "max_angular_distortion",
                    "max_fissure_prone_length_m"):
            assert float(two[plan][key]) == pytest.approx(float(one[plan][key]), rel=1e-10), (plan, key)


@pytest.mark.parametrize("plans, message", [
    ("[halved]\n-pfault_flow_well_rates 0:0,1*day:1.5*L/s\n", "line 2: unknown option -pfault_flow_well_rates"),
    ("[halved]\n[none]\n-pfault_flow_well_rate 0:0,1*day:0\n", "line 1: plan 'halved' sets no option"),
    ("[a]\n-pfault_flow_well_rate 0:0,1*day:0\n[A]\n-pfault_time_steps 1\n", "line 3: a second plan named 'A'"),
    ("[baseline]\n-pfault_time_steps 1\n", "line 1: the plan name 'baseline' is the scene as it is"),
    ("-pfault_time_steps 1\n", "no plan"),
    ("[late]\n-pfault_flow_well_rate 1*day:0,0:0\n", "line 2: -pfault_flow_well_rate: times in"),
    ("[out]\n-pfault_output_dir elsewhere\n", "line 2: -pfault_output_dir cannot be set in a plan"),
    ("[two]\n-pfault_time_steps 1 -pfault_time_end 1*day\n", "line 2: '-pfault_time_steps 1 -pfault_time_end"),
    ("[bad name]\n-pfault_time_steps 1\n", "line 1: '[bad name]' is not a plan header"),
])
def test_bad_plans_files_are_one_line_and_write_nothing(tmp_path, plans, message):
    proc, out = scenarios(tmp_path, plans)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pfault: error: ") and message in lines[0], proc.stderr
    assert str(tmp_path / "plans.opts") in lines[0]
    assert proc.stdout == "" and not out.exists()


def test_a_bad_scene_or_missing_plans_file_is_one_line(tmp_path):
    proc, out = scenarios(tmp_path, PLANS, scene="-pfault_time_steps 1 2\n")
    assert proc.returncode == 1 and len(proc.stderr.strip().splitlines()) == 1 and "box.opts line 1" in proc.stderr
    assert not out.exists()
    proc = run(["-m", "pfault.scenarios", "config/oedometer.opts", str(tmp_path / "nope.opts")], timeout=TIMEOUT,
               check=False)
    assert proc.returncode == 1 and "nope.opts: cannot read it" in proc.stderr
    proc = run(["-m", "pfault.scenarios", "config/oedometer.opts"], timeout=TIMEOUT, check=False)
    assert proc.returncode == 2 and proc.stderr.startswith("usage: python -m pfault.scenarios")


def test_an_output_directory_that_cannot_be_made_is_one_line(tmp_path):
    (tmp_path / "out").write_text("a file in the way")
    proc, out = scenarios(tmp_path, PLANS)
    assert proc.returncode == 4, proc.stdout + proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith(f"pfault: error: --output {out}: cannot make")
    assert out.read_text() == "a file in the way"
