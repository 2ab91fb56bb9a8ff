"""A scene builds only the effects it asks for: the effects record in summary.json, the fields, and PETSc's own
object and event counts (-log_view) show what was built."""

import re

import pytest

from conftest import OEDOMETER, TWO_BLOCKS, run_scene

EFFECTS = ("faults", "flow", "pressure_tables", "geostatic", "tractions", "displacements")


def log_counts(path):
    """(objects created per type, summed over stages; event call counts) from a -log_view file."""
    objects, events = {}, {}
    text = open(path).read()
    head, _, tail = text.partition("Object Type")
    for line in head.splitlines():
        m = re.match(r"^(pfault\w+|KSPSolve|SNESSolve|MatLUFactorNum)\s+(\d+)\s", line)
        if m:
            events[m.group(1)] = events.get(m.group(1), 0) + int(m.group(2))
    for line in tail.splitlines():
        m = re.match(r"^\s+([A-Za-z][A-Za-z ]*?)\s+(\d+)\s+(\d+)\b", line)
        if m:
            objects[m.group(1)] = objects.get(m.group(1), 0) + int(m.group(2))
    return objects, events


def run(tmp_path, name, scene, extra=(), ranks=1):
    out = tmp_path / name
    lv = tmp_path / f"{name}.log_view"
    proc, s = run_scene(scene, out, ranks=ranks, extra=[*extra, "-log_view", f":{lv}"])
    objects, events = log_counts(lv)
    line = [ln for ln in proc.stdout.splitlines() if "effects:" in ln]
    return s, objects, events, line


def scene_file(tmp_path, name, base, drop=(), add=()):
    """An options file: ``base`` without the options starting with any of ``drop``, plus ``add`` lines."""
    lines = [ln for ln in open(base).read().splitlines() if not ln.strip().startswith(tuple(drop))]
    path = tmp_path / f"{name}.opts"
    path.write_text("\n".join(lines + list(add)) + "\n")
    return str(path)


def on(summary):
    return {k for k, v in summary["effects"].items() if v["on"]}


def test_scene_without_faults_or_flow_builds_neither(tmp_path):
    s, objects, events, line = run(tmp_path, "oed", OEDOMETER)
    assert on(s) == {"pressure_tables"}
    assert s["fields"] == ["displacement"]                      # no lagrange_multiplier_fault field
    assert objects["Krylov Solver"] == 1                        # the skeleton's only: no flow KSP
    assert not any(e.startswith("pfaultFault") for e in events)  # no contact code ran
    assert "pfaultGeostatic" not in events and "pfaultFlowSolve" not in events
    assert len(line) == 1 and "faults off" in line[0] and "groundwater flow off" in line[0]
    assert s["effects"]["pressure_tables"]["per_step_s"] > 0
    assert s["effects"]["faults"]["setup_s"] == 0.0


def test_faults_add_exactly_the_multiplier_field_and_the_contact_work(tmp_path):
    with_f, o1, e1, _ = run(tmp_path, "f", "config/two_blocks.opts")
    glued = scene_file(tmp_path, "glued", TWO_BLOCKS, drop=("-pfault_faults", "-pfault_fault_"))
    without, o0, e0, _ = run(tmp_path, "nof", glued)
    assert on(with_f) - on(without) == {"faults"} and on(without) <= on(with_f)
    assert with_f["fields"] == ["displacement", "lagrange_multiplier_fault"]
    assert without["fields"] == ["displacement"]
    assert e1["pfaultFaultResidual"] > 0 and e1["pfaultFaultJacobian"] > 0
    assert not any(e.startswith("pfaultFault") for e in e0)
    assert o1["Krylov Solver"] == o0["Krylov Solver"]
    assert with_f["effects"]["faults"]["per_step_s"] > 0


def test_flow_adds_its_ksp_and_nothing_else(tmp_path):
    """The oedometer column loaded by a well (flow model) against the same column loaded by a pressure table."""
    flow_scene = scene_file(tmp_path, "flow", OEDOMETER, drop=("-pfault_material_soil_pressure_change",),
                            add=["-pfault_flow true", "-pfault_material_soil_hydraulic_conductivity 1e-5",
                                 "-pfault_flow_fixed_head_surfaces top", "-pfault_flow_wells 5,5",
                                 "-pfault_flow_well_screen -20,-80", "-pfault_flow_well_rate 0:0,10:1e-3"])
    flow, o1, e1, _ = run(tmp_path, "flow", flow_scene)
    tables, o0, e0, _ = run(tmp_path, "tables", OEDOMETER)
    assert on(flow) ^ on(tables) == {"flow", "pressure_tables"}
    assert o1["Krylov Solver"] == o0["Krylov Solver"] + 1          # the flow_ KSP
    assert e1["pfaultFlowSolve"] > 0 and "pfaultFlowSolve" not in e0
    assert flow["fields"] == tables["fields"]
    assert flow["effects"]["flow"]["setup_s"] > 0 and flow["effects"]["flow"]["per_step_s"] > 0


def test_geostatic_start_is_the_only_change(tmp_path):
    plain, _, e0, _ = run(tmp_path, "plain", OEDOMETER)
    geo, _, e1, _ = run(tmp_path, "geo", OEDOMETER, ["-pfault_geostatic", "true"])
    assert on(geo) - on(plain) == {"geostatic"}
    assert e1["pfaultGeostatic"] == 1 and "pfaultGeostatic" not in e0
    assert geo["effects"]["geostatic"]["setup_s"] > 0 and geo["effects"]["geostatic"]["per_step_s"] == 0.0


@pytest.mark.parametrize("ranks", [2])
def test_effects_record_is_the_same_on_two_ranks(tmp_path, ranks):
    one, _, _, _ = run(tmp_path, "r1", TWO_BLOCKS)
    two, _, _, _ = run(tmp_path, "r2", TWO_BLOCKS, ranks=ranks)
    assert {k: (v["on"], v["detail"]) for k, v in one["effects"].items()} == \
        {k: (v["on"], v["detail"]) for k, v in two["effects"].items()}
