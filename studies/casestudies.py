"""The two case studies of Franceschini et al. (Proc. IAHS 372, 63-68, 2015) against the paper.

    .venv/bin/python -m studies.casestudies                 # run all, figures, rewrite runs/README.md
    .venv/bin/python -m studies.casestudies --no-run        # figures + README from the existing runs
    .venv/bin/python -m studies.casestudies --cases wuxi --solver iterative   # a solver variant
    .venv/bin/python -m studies.casestudies --cases wuxi --tag lag -- -snes_lag_preconditioner 100

Each case runs as ``mpirun -n RANKS python -m pfault config/<case>.opts -pfault_output_dir runs/<run>
-log_view :runs/<run>/log_view.txt -pfault_contact_monitor [options after --]`` (one at a time: the
reference machine has 2 cores), with stdout in ``runs/<run>/stdout.txt`` and the driver's own record
(command, exit code, end-to-end wall time including MPI start-up and imports, CPU time, load average
during the run) in ``runs/<run>/casestudy.json``. ``<run>`` is the case name, suffixed ``-<tag>``,
``-<solver>`` for a solver other than mumps and ``-f<factor>`` for a mesh size factor other than 1. Then
the figures of pfault.post.figures are written into each run directory and ``runs/README.md`` is
regenerated from every run directory found.

The paper's figures are the ones quoted in its text (nothing digitised from its plots): where it gives a
shape rather than a number, the tables say so.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time

from pfault.post import figures, meshes, rundir
from pfault.units import YEAR

from pfault.tools.runs import command, cpu_model, run_logged, shown

from . import REPO

CASES = {
    "wuxi": "config/wuxi.opts",
    "queretaro": "config/queretaro.opts",
    "queretaro_calibrated": "config/queretaro_calibrated.opts",
}
# what the paper states in its text (Franceschini et al. 2015)
PAPER = {
    "wuxi": {"nodes": 23303, "tets": 121942, "fault_faces": 1876, "max_opening_m": 0.2, "opening_text": "about 0.2 m",
             "slip_text": "negligible", "subsidence_text": "bowl shaped by the bedrock burial depth (Fig. 4)",
             "drawdown_text": "prescribed: 20 m (sands), 10 m (clays)"},
    "queretaro": {"nodes": 57050, "tets": 297971, "fault_faces": 8074, "max_slip_m": 0.4, "max_drawdown_m": 20.0,
                  "opening_text": "< 3 cm", "slip_text": "approaching 0.4 m",
                  "subsidence_text": "same order as the slip (~0.4 m); largest in the upper central part near "
                                     "the wells (Fig. 7)",
                  "drawdown_text": "~20 m"},
}
PAPER["queretaro_calibrated"] = PAPER["queretaro"]
# Options every run of a case gets from the driver (shown in its command); none at present.
CASE_OPTIONS = {}
CONVERGENCE_NOTE = (
    "Each step is one semismooth Newton solve run by SNES from the step's elastic trial (README, \"Faults and "
    "fissures\"); a step whose Newton solve diverges would be redone in sub-steps (`-pfault_time_max_cuts`), "
    "and the step tables say when one was.")
OPEN = 2                                   # fault face state code in fault.xdmf (pfault.faults.contact)
STAGES = ("Mesh", "Setup", "Solve", "Output")
EVENTS = ("MatLUFactorNum", "MatLUFactorSym", "MatSolve", "KSPSolve", "PCSetUp", "SNESFunctionEval",
          "SNESJacobianEval", "pfaultFlowSolve", "pfaultFlowAssemble", "pfaultAssembleK")


def run_name(case, solver="mumps", size_factor=1.0, tag=""):
    name = case
    if tag:
        name += f"-{tag}"
    if solver != "mumps":
        name += f"-{solver}"
    if float(size_factor) != 1.0:
        name += f"-f{float(size_factor):g}"
    return name


# ------------------------------------------------------------------------------------------------------
# running
# ------------------------------------------------------------------------------------------------------
def run_case(case, ranks=2, solver="mumps", size_factor=1.0, extra=(), timeout=7200, runs_dir="runs", tag=""):
    """Runs one case under mpirun from the repository root; returns the driver record (also written to
    runs/<run>/casestudy.json)."""
    name = run_name(case, solver, size_factor, tag)
    out = os.path.join(runs_dir, name)
    os.makedirs(os.path.join(REPO, out), exist_ok=True)
    args = [CASES[case], "-pfault_output_dir", out, "-log_view", f":{out}/log_view.txt", "-pfault_contact_monitor"]
    args += ["-pfault_solver", solver]      # named always: the scenes' own choice is auto
    if float(size_factor) != 1.0:
        args += ["-pfault_mesh_size_factor", f"{float(size_factor):g}"]
    args += CASE_OPTIONS.get(case, []) + list(extra)
    print(f"case studies: {name}: {shown(command(['-m', 'pfault', *args], ranks))}", flush=True)
    for stale in ("summary.json", "casestudy.json"):
        path = os.path.join(REPO, out, stale)
        if os.path.exists(path):
            os.remove(path)
    done = run_logged(["-m", "pfault", *args], ranks, os.path.join(REPO, out, "stdout.txt"), timeout, cwd=REPO)
    rec = {"case": case, "run": name, "tag": tag, "extra": list(extra), "command": done.command, "ranks": ranks,
           "solver": solver, "size_factor": float(size_factor), "exit_code": done.code,
           "wall_end_to_end_s": done.wall, "cpu_s": done.cpu, "load_avg_1min_mean": done.load,
           "load_avg_1min_max": max(done.loads), "date": time.strftime("%Y-%m-%d %H:%M"),
           "host_cpus": os.cpu_count(), "cpu_model": cpu_model()}
    with open(os.path.join(REPO, out, "casestudy.json"), "w") as fh:
        json.dump(rec, fh, indent=2)
    status = "done" if done.code == 0 else f"EXIT {done.code}"
    print(f"case studies: {name}: {status} in {done.wall:.1f} s (mean load {rec['load_avg_1min_mean']:.2f})",
          flush=True)
    return rec


# ------------------------------------------------------------------------------------------------------
# reading a finished run
# ------------------------------------------------------------------------------------------------------
def parse_log_view(path):
    """Stage times (s, average over ranks) and, per stage, {event: (count, max time s)} from -log_view."""
    stages, events = {}, {}
    if not os.path.exists(path):
        return stages, events
    with open(path) as fh:
        text = fh.read().split("\n")
    in_summary, current = False, None
    stage_re = re.compile(r"^\s*\d+:\s+(.+?):\s+([0-9.eE+-]+)\s")
    for line in text:
        if line.startswith("Summary of Stages"):
            in_summary = True
            continue
        if in_summary:
            m = stage_re.match(line)
            if m:
                stages[m.group(1).strip()] = float(m.group(2))
            elif line.startswith("---"):
                in_summary = False
            continue
        m = re.match(r"^--- Event Stage \d+: (.+)$", line)
        if m:
            current = m.group(1).strip()
            events.setdefault(current, {})
            continue
        if current is not None:
            parts = line.split()
            if len(parts) > 4 and parts[0] in EVENTS:
                try:
                    events[current].setdefault(parts[0], (int(float(parts[1])), float(parts[3])))
                except ValueError:
                    pass
        if line.startswith("Object Type") or line.startswith("Memory usage"):
            current = None
    return stages, events


def _stdout_tail(run_dir, n=14):
    path = os.path.join(run_dir, "stdout.txt")
    if not os.path.exists(path):
        return []
    with open(path) as fh:
        lines = [ln.rstrip() for ln in fh if ln.startswith(("step", "  active set"))]
    return lines[-n:]


def collect(run_dir):
    """Everything the README reports about one run directory (None if it holds no finished run).

    Maxima are taken over the converged steps only (summary.json's own maxima include a step that did not
    converge); the nodal surface jumps and dip slips come from the last converged output."""
    if not os.path.exists(os.path.join(run_dir, "summary.json")):
        return None
    summary = rundir.read_summary(run_dir)
    rec = {}
    path = os.path.join(run_dir, "casestudy.json")
    if os.path.exists(path):
        with open(path) as fh:
            rec = json.load(fh)
    stages, events = parse_log_view(os.path.join(run_dir, "log_view.txt"))
    steps = [s for s in summary["steps"] if not s.get("initial")]
    good = [s for s in steps if s.get("converged", True)]
    out = {"dir": run_dir, "summary": summary, "driver": rec, "stages": stages, "events": events,
           "converged": bool(summary.get("converged")), "steps_done": len(good), "steps_total": len(steps),
           "newton_total": int(sum(s.get("newton_its", 0) for s in steps)),
           "ksp_total": int(sum(s.get("ksp_its", 0) for s in steps)),
           "substeps_total": int(sum(max(s.get("substeps", 1), 1) - 1 for s in steps)),
           "tail": [] if summary.get("converged") else _stdout_tail(run_dir)}
    for key in ("max_subsidence_m", "max_horizontal_displacement_m", "max_fault_opening_m", "max_fault_slip_m",
                "max_drawdown_m"):
        out[key] = max([s.get(key, 0.0) for s in good], default=0.0)
    out["last_time_yr"] = good[-1]["time_s"] / YEAR if good else 0.0
    if rundir.has_fault(run_dir) and good:
        every = int(rundir.read_options(run_dir).get("pfault_output_every", "1") or 1)
        step = -1 if summary.get("converged") else -2
        if every == 1 or summary.get("converged"):
            fields, fault = rundir.read_fields(run_dir, step), rundir.read_fault(run_dir, step)
            out["surface_opening_m"], out["surface_slip_m"] = meshes.surface_fault_jumps(fields, fault)
            normals, area, _ = meshes.face_geometry(fault.points, fault.cells)
            dip = meshes.dip_slip(fault.cell_data["slip"], normals)
            out["dip_slip_min_m"], out["dip_slip_max_m"] = float(dip.min()), float(dip.max())
            out["open_fraction"] = float(area[fault.cell_data["state"] == OPEN].sum() / area.sum())
    return out


# ------------------------------------------------------------------------------------------------------
# README
# ------------------------------------------------------------------------------------------------------
def _m(v, unit="m", digits=3):
    if v is None:
        return "—"
    if unit == "cm":
        return f"{100.0 * v:.{digits}g} cm"
    if unit == "mm":
        return f"{1000.0 * v:.{digits}g} mm"
    return f"{v:.{digits}g} m"


def _face_and_surface(r, what, unit):
    """'<face-average maximum> (face average; <nodal maximum at the land surface> at the surface)' of a run's fault
    ``what`` (opening or slip)."""
    return (f"{_m(r[f'max_fault_{what}_m'], unit)} (face average; {_m(r.get(f'surface_{what}_m'), unit)} at the "
            "surface)")


def _dev(got, paper):
    return f"{100.0 * (got / paper - 1.0):+.1f} %"


def _s(v):
    return "—" if v is None else f"{v:.1f}"


def _status(r):
    s = r["summary"]
    if s.get("converged"):
        return "converged"
    bad = next((i for i, st in enumerate(s["steps"]) if not st.get("converged", True)), None)
    return f"**did not converge** (step {bad}; maxima up to step {bad - 1 if bad else '?'})"


def results_table(runs, case):
    """Paper against one column per run of the case (default run first, then variants)."""
    p = PAPER[case]
    head = "| quantity | paper | " + " | ".join(f"`{os.path.basename(r['dir'])}`" for r in runs) + " |"
    lines = [head, "|---|---|" + "---|" * len(runs)]

    def row(label, paper, cells):
        lines.append(f"| {label} | {paper} | " + " | ".join(cells) + " |")

    row("status", "", [_status(r) for r in runs])
    row("max fault opening: face average (summary.json)", p["opening_text"],
        [_m(r["summary"]["max_fault_opening_m"], "cm") for r in runs])
    row("max fault opening: nodal, at the land surface", p["opening_text"],
        [_m(r.get("surface_opening_m"), "cm") for r in runs])
    row("max fault slip: face average", p["slip_text"], [_m(r["summary"]["max_fault_slip_m"], "cm") for r in runs])
    row("max fault slip: nodal, at the land surface", p["slip_text"], [_m(r.get("surface_slip_m"), "cm") for r in runs])
    row("dip slip u_z(plus) − u_z(minus), range over faces (plus side: x > fault)", "—",
        [f"{_m(r.get('dip_slip_min_m'), 'cm')} … {_m(r.get('dip_slip_max_m'), 'cm')}" for r in runs])
    row("max land subsidence", p["subsidence_text"], [_m(r["summary"]["max_subsidence_m"]) for r in runs])
    row("max horizontal displacement of the land surface", "—",
        [_m(r["summary"]["max_horizontal_displacement_m"]) for r in runs])
    row("max drawdown", p["drawdown_text"],
        [f"{r['max_drawdown_m']:.3g} m (flow model)" if r["max_drawdown_m"] else "prescribed" for r in runs])
    row("fault area open at the end", "—", [f"{100.0 * r.get('open_fraction', 0.0):.0f} %" for r in runs])
    for key, label, paper in (("nodes", "mesh nodes", p["nodes"]), ("cells", "mesh tetrahedra", p["tets"]),
                              ("fault_faces", "interface (fault) faces", p["fault_faces"])):
        row(label, f"{paper:,}", [f"{r['summary']['mesh'][key]:,} ({_dev(r['summary']['mesh'][key], paper)})"
                                  for r in runs])
    return "\n".join(lines)


def timing_table(results):
    lines = ["| run | ranks | solver | dofs | mesh s | setup s | solve s | output s | total s (pfault) | "
             "end to end s (mpirun) | CPU s / rank | mean load | Newton its (worst step) | LU factorisations | sub-steps | "
             "exit |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        s, d, w = r["summary"], r["driver"], r["summary"].get("wall_s", {})
        cpu = d.get("cpu_s")
        lines.append(f"| {os.path.basename(r['dir'])} | {s['ranks']} | {d.get('solver', '?')} | {s['dofs']:,} | "
                     f"{_s(w.get('mesh'))} | {_s(w.get('setup'))} | {_s(w.get('solve'))} | {_s(w.get('output'))} | "
                     f"{_s(w.get('total'))} | {_s(d.get('wall_end_to_end_s'))} | "
                     f"{_s(cpu / s['ranks'] if cpu is not None else None)} | "
                     f"{d.get('load_avg_1min_mean', float('nan')):.1f} | {r['newton_total']} "
                     f"({max((st.get('newton_its', 0) for st in s['steps']), default=0)}) | "
                     f"{sum(st.get('factorizations', 0) for st in s['steps'])} | {r['substeps_total']} | "
                     f"{d.get('exit_code', '?')} |")
    return "\n".join(lines)


def where_time_goes(r):
    st, ev = r["stages"], r["events"].get("Solve", {})
    if not st:
        return "(no -log_view output)"
    parts = [f"PETSc stages (s, average over ranks): " + ", ".join(f"{k} {st[k]:.1f}" for k in STAGES if k in st)]
    solve = st.get("Solve", 0.0)
    items = []
    for name in ("MatLUFactorNum", "MatLUFactorSym", "MatSolve", "PCSetUp", "KSPSolve", "SNESFunctionEval",
                 "SNESJacobianEval", "pfaultFlowSolve"):
        if name in ev:
            n, t = ev[name]
            share = f", {100.0 * t / solve:.0f} % of Solve" if solve > 0 else ""
            items.append(f"{name} {n}x {t:.1f} s ({t / max(n, 1):.2f} s each{share})")
    if items:
        parts.append("in Solve: " + "; ".join(items))
    return ". ".join(parts) + "."


def steps_table(r):
    steps = r["summary"]["steps"]
    flow = any("max_drawdown_m" in s for s in steps)
    head = ("| step | t (yr) | Newton | KSP | LU | sub-steps | stick/slip/open | wall s | subsidence m | opening cm | "
            "slip cm |" + (" drawdown m |" if flow else ""))
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    first = 0 if steps and steps[0]["time_s"] == 0 else 1     # step 0 is the initial (geostatic) state
    for i, s in enumerate(steps, start=first):
        row = (f"| {i} | {s['time_s'] / YEAR:.3g} | {s.get('newton_its', 0)} | {s.get('ksp_its', 0)} | "
               f"{s.get('factorizations', '—')} | {max(s.get('substeps', 1), 1) - 1} | {s.get('stick', '—')}/{s.get('slip', '—')}/{s.get('open', '—')} | "
               f"{s.get('wall_s', 0.0):.1f} | {s.get('max_subsidence_m', 0.0):.3g} | "
               f"{100.0 * s.get('max_fault_opening_m', 0.0):.3g} | {100.0 * s.get('max_fault_slip_m', 0.0):.3g} |")
        if flow:
            row += f" {s.get('max_drawdown_m', 0.0):.3g} |"
        lines.append(row + ("" if s.get("converged", True) else " **not converged**"))
    return "\n".join(lines)


def _case_of(r):
    return os.path.basename(r["dir"]).split("-")[0]


def _default_run(results, case):
    """The run of the case made with the default solver at paper size and no extra options."""
    for r in results:
        d = r["driver"]
        if (os.path.basename(r["dir"]) == case and d.get("solver", "mumps") == "mumps"
                and float(d.get("size_factor", 1.0)) == 1.0 and not d.get("extra")):
            return r
    return None


def summary_table(results):
    """Compact paper-vs-pfault table over the default runs."""
    cols = [(c, _default_run(results, c)) for c in CASES]
    cols = [(c, r) for c, r in cols if r is not None]
    if not cols:
        return "(no runs)"
    head = "| | " + " | ".join(f"{c}: paper | {c}: pfault" for c, _ in cols) + " |"
    lines = [head, "|---|" + "---|---|" * len(cols)]

    def row(label, fn):
        cells = []
        for c, r in cols:
            paper, ours = fn(PAPER[c], r)
            cells += [paper, ours]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")

    row("status", lambda p, r: ("", _status(r)))
    row("max opening (surface node / face average)",
        lambda p, r: (p["opening_text"], f"{_m(r.get('surface_opening_m'), 'cm')} / {_m(r['max_fault_opening_m'], 'cm')}"))
    row("max slip (surface node / face average)",
        lambda p, r: (p["slip_text"], f"{_m(r.get('surface_slip_m'), 'cm')} / {_m(r['max_fault_slip_m'], 'cm')}"))
    row("max subsidence", lambda p, r: (p["subsidence_text"], _m(r["max_subsidence_m"])))
    row("max drawdown", lambda p, r: (p["drawdown_text"],
                                      f"{r['max_drawdown_m']:.3g} m" if r["max_drawdown_m"] else "prescribed"))
    for key, label, pk in (("nodes", "nodes", "nodes"), ("cells", "tetrahedra", "tets"),
                           ("fault_faces", "interface faces", "fault_faces")):
        row(label, lambda p, r, key=key, pk=pk: (f"{p[pk]:,}", f"{r['summary']['mesh'][key]:,} "
                                                              f"({_dev(r['summary']['mesh'][key], p[pk])})"))
    row("wall time, 2 ranks, end to end (target)",
        lambda p, r: ("", f"{_s(r['driver'].get('wall_end_to_end_s'))} s (≤ {TARGETS[_case_of(r)][0]:.0f} s)"))
    return "\n".join(lines)


def _variant(results, case, tag, any_size=False):
    """The run of a case variant at paper size or, with ``any_size``, failing that at the finest size factor
    run; None if there is none."""
    runs = [r for r in results if _case_of(r) == case and (r["driver"] or {}).get("tag") == tag]
    for r in runs:
        if float(r["driver"].get("size_factor", 1.0)) == 1.0:
            return r
    if any_size and runs:
        return min(runs, key=lambda r: float(r["driver"].get("size_factor", 1.0)))
    return None


def _loading_steps(r):
    """(step number, record) of a run's loading steps, numbered from 1 (the initial state, when a run has one,
    is step 0)."""
    return [(n, st) for n, st in enumerate((st for st in r["summary"]["steps"] if st.get("time_s", 0) > 0), 1)]


def _finest(results, case, tag=""):
    """The converged run of a case variant (``tag``; no extra options when untagged) on the finest mesh finer
    than the paper's (size factor < 1), or None."""
    finer = [r for r in results if _case_of(r) == case and r["converged"]
             and (r["driver"] or {}).get("tag", "") == tag and (tag or not r["driver"].get("extra"))
             and float(r["driver"].get("size_factor", 1.0)) < 1.0]
    return min(finer, key=lambda r: float(r["driver"]["size_factor"])) if finer else None


def discussion(results):
    """Paragraphs comparing pfault with the paper; the numbers come from the runs, the reasons are ours."""
    out = []
    w = _default_run(results, "wuxi")
    if w is not None:
        text = (
            "**Wuxi: the fissure opens and barely slides, as in the paper; the opening, "
            f"{_m(w['max_fault_opening_m'], 'cm')} (face average; {_m(w.get('surface_opening_m'), 'cm')} at the land "
            "surface, nodal jump), is of the paper's ~0.2 m with our ridge (flanks dipping 43 degrees), and it "
            "grows with the flank dip.** "
            f"{100.0 * w.get('open_fraction', 0.0):.0f} % of the fissure faces are open after 10 years; the largest "
            f"slip is {_m(w['max_fault_slip_m'], 'mm')}; the subsidence bowl follows the bedrock burial depth "
            f"({_m(w['max_subsidence_m'])} where the compressible cover is 100 m thick, centimetres over the crest, "
            "subsidence_map.png). Why it opens: the 10 m of drawdown in the clays lowers the water table below the "
            "5 m deep fissure after 5 years, so the fissure is dry (its pore pressure is clamped at zero) and its "
            "faces carry the total stress, which the drawdown turns tensile: in lateral confinement the effective "
            "horizontal stress grows by nu/(1-nu) = 0.43 times the pressure drop while the pore pressure falls by "
            "all of it, a net horizontal tension of 0.57 x 98 kPa = 56 kPa per 10 m of head against a geostatic "
            "total compression of ~14 kPa per metre of depth; the differential compaction of the cover on the two "
            "flanks pulls the fissure's sides apart.")
        fr = _finest(results, "wuxi")
        if fr is not None:
            text += (f" The opening is mesh-converged: {_face_and_surface(fr, 'opening', 'cm')} at size factor "
                     f"{float(fr['driver']['size_factor']):g} ({fr['summary']['mesh']['nodes']:,} nodes); the "
                     f"slip, {_m(fr['max_fault_slip_m'], 'mm')} there, is not, but it stays a few millimetres.")
        text += (
            " What sets the magnitude: the opening is the difference of the horizontal displacements of the two "
            "flanks, which grows with the flank dip and with the contrast of cover thickness. The ridge is ours "
            "(crest 5 m deep, flanks dipping 43 degrees to a bedrock 100 m deep 100 m away on each side, clay/sand "
            "interfaces at 20, 50 and 80 m; config/wuxi.opts); the paper does not give its profile.")
        wg = _variant(results, "wuxi", "gentle")
        if wg is not None:
            text += (
                f" With flanks dipping 11 degrees (`{os.path.basename(wg['dir'])}`, "
                f"`-pfault_wuxi_ridge_half_width 500`) the opening is {_face_and_surface(wg, 'opening', 'cm')}, "
                f"for the same subsidence ({_m(wg['max_subsidence_m'])}) and a slip of "
                f"{_m(wg['max_fault_slip_m'], 'mm')}.")
        ws = _variant(results, "wuxi", "suction")
        if ws is not None:
            text += (
                f" Keeping the suction instead (`{os.path.basename(ws['dir'])}`, `-pfault_contact_suction true`: the "
                "negative pore pressure above the lowered water table, down to -98 kPa at the surface, presses the "
                f"faces together) the fissure opens less: {_face_and_surface(ws, 'opening', 'cm')}, "
                f"{100.0 * ws.get('open_fraction', 0.0):.1f} % of the faces open at the end")
            frs = _finest(results, "wuxi", "suction")
            if frs is not None:
                text += (
                    f" ({_m(frs['max_fault_opening_m'], 'cm')} at size factor "
                    f"{float(frs['driver']['size_factor']):g}): on this ridge the flanks' differential compaction "
                    "opens the fissure even against the suction.")
            else:
                text += "."
        text += (
            " Other likely differences: the geometry does not vary along the ridge here, and the fissure is one "
            "element deep, its jump pinned to zero on the crest 5 m below ground.")
        out.append(text)
    q = _default_run(results, "queretaro")
    qc = _default_run(results, "queretaro_calibrated")
    if q is not None or qc is not None:
        parts = ["**Querétaro: the fault slides with the sediment side going down and opens little, as in the paper; "
                 "the magnitudes depend on the drawdown, and no single parameter set matches all the paper's "
                 "figures.**"]
        if q is not None:
            parts.append(
                f"With the flow parameters as stated (3 wells × 300 L/s, K = 1e-4 m/s in a 30 m aquifer, S_s from the "
                f"skeleton compressibility) the head drops by {q['max_drawdown_m']:.3g} m at the wells "
                f"(up to t = {q['last_time_yr']:.3g} years), not ~20 m: a Thiem estimate gives Q/(2π K b) = 16 m per "
                "logarithmic unit of distance per well, so ~100 m or more at a well node tens of metres wide with "
                f"the fixed-head boundaries 18 km away. Subsidence ({_m(q['max_subsidence_m'])}) and slip "
                f"({_m(q['max_fault_slip_m'])}) are then of the same order, as the paper says, but several times larger "
                "than its ~0.4 m. Such a head lies far below the bottom of the 50 m deep aquifer, which would be "
                "dewatered: the confined, saturated flow model is outside its range there, and the fault faces whose "
                f"pore pressure would be negative are dry (clamped at zero), so the fault opens by up to "
                f"{_m(q['max_fault_opening_m'], 'cm')}.")
        if qc is not None:
            parts.append(
                f"The calibrated variant scales the well rate to 41.5 L/s (config/queretaro_calibrated.opts) and "
                f"draws the head down by {qc['max_drawdown_m']:.3g} m: the subsidence "
                f"({_m(qc['max_subsidence_m'])}, largest at the wells, on the sediment side) and the opening "
                f"({_m(qc['max_fault_opening_m'], 'cm')} face average, {_m(qc.get('surface_opening_m'), 'cm')} at the "
                "surface, paper < 3 cm) then agree with the paper, but the slip does not: "
                f"{_face_and_surface(qc, 'slip', 'cm')} instead of ~0.4 m. The soft clay next to the fault hangs "
                "on it: most of the offset between rock and sediments is taken by shear of the first row of "
                "elements on the sediment side rather than by slip, because the geostatic effective normal stress on the fault (K0 σ'v, growing further as the "
                "pore pressure drops) gives it a frictional strength the drawdown-induced shear only partly "
                "overcomes. Because that shear is carried by one row of elements, the slip depends on the mesh: "
                "it falls as the mesh is refined (section \"Accuracy against cost\").")
        qw = _variant(results, "queretaro_calibrated", "wells500")
        if qw is not None:
            parts.append(
                f"With the wells 500 m from the fault instead of 2 km (`{os.path.basename(qw['dir'])}`, "
                "`-pfault_flow_wells 10500,12000,10500,15000,10500,18000`, the rate recalibrated to 32.6 L/s for "
                f"the same {qw['max_drawdown_m']:.3g} m of drawdown) the drawdown cone reaches the fault with more "
                f"of its depth: the slip grows to {_face_and_surface(qw, 'slip', 'cm')} and the subsidence to "
                f"{_m(qw['max_subsidence_m'])}, with an opening of {_m(qw['max_fault_opening_m'], 'cm')}; closer to "
                "the paper's slip, still short of ~0.4 m.")
        qn = _variant(results, "queretaro_calibrated", "nogeostatic", any_size=True)
        if qn is not None:
            f_n = float(qn["driver"].get("size_factor", 1.0))
            base_name = run_name("queretaro_calibrated", size_factor=f_n)
            same = [r for r in results if os.path.basename(r["dir"]) == base_name and r["converged"]]
            at = "" if f_n == 1.0 else f" at size factor {f_n:g}"
            notes = [f"step {n} in {st['substeps']} sub-steps" for n, st in _loading_steps(qn)
                     if st.get("substeps", 1) > 1]
            cut_text = ", ".join(notes)
            parts.append(
                f"Without the geostatic stress (`{os.path.basename(qn['dir'])}`, `-pfault_geostatic false`{at}: the "
                "stresses are the pumping's increments only, and the c = 0 fault starts with no strength, its "
                "Coulomb limit coming from the drawdown alone) the sediments slide down the rock: the slip is "
                f"{_face_and_surface(qn, 'slip', 'cm')}, {100.0 * qn['max_fault_slip_m'] / qn['max_subsidence_m']:.0f} % "
                f"of the subsidence ({_m(qn['max_subsidence_m'])}), and the fault opens by "
                f"{_face_and_surface(qn, 'opening', 'cm')}, {qn['summary']['steps'][-1].get('open', 0):,} of its "
                f"{qn['summary']['mesh']['fault_faces']:,} faces open at the end"
                + (f" (with it, on the same mesh: slip {_m(same[0]['max_fault_slip_m'], 'cm')}, opening "
                   f"{_m(same[0]['max_fault_opening_m'], 'cm')})" if same else "")
                + ": the paper's picture (slip of the order of the subsidence, opening < 3 cm) comes closer "
                "without the initial friction than with it. "
                "The paper does not say whether its fault carried an initial stress. The fault of zero initial "
                f"strength takes {qn['newton_total']} Newton iterations over the run, at most "
                f"{max(st.get('newton_its', 0) for _, st in _loading_steps(qn))} in a step"
                + (f" ({cut_text})." if cut_text else ", without sub-steps."))
        qwn = _variant(results, "queretaro_calibrated", "wells500-nogeostatic")
        if qwn is not None:
            parts.append(
                f"Both together (`{os.path.basename(qwn['dir'])}`: wells 500 m from the fault at 32.6 L/s and no "
                f"geostatic stress; drawdown {qwn['max_drawdown_m']:.3g} m) come closest to the paper's figures: "
                f"slip {_face_and_surface(qwn, 'slip', 'cm')}, "
                f"{100.0 * qwn['max_fault_slip_m'] / qwn['max_subsidence_m']:.0f} % of the subsidence "
                f"({_m(qwn['max_subsidence_m'])}), opening {_face_and_surface(qwn, 'opening', 'cm')}.")
        parts.append(
            "Other likely differences: the geometry is ours (vertical fault through the whole 50 m, wells 2 km from "
            "it, clay 20 m over a 30 m aquifer, fixed-head far boundaries), and the maximum drawdown sits at the "
            "well nodes where it grows like ln(1/h) with the element size h (a line sink), so it is a soft "
            "calibration target: 41.5 L/s gives 20.0 m at size factor 1 but ~15 m at size factor 3-4.")
        out.append(" ".join(parts))
    return "\n\n".join(out)


def convergence_text(results):
    out = []
    for r in results:
        if r["converged"]:
            continue
        bad = r["steps_total"] - r["steps_done"]
        st = [s for s in r["summary"]["steps"] if not s.get("converged", True)]
        reason = st[0].get("reason") if st else "?"
        out += [f"- `{os.path.basename(r['dir'])}` did not converge at step {r['steps_done'] + 1} "
                f"(t = {r['last_time_yr'] + (r['summary']['steps'][1]['time_s'] / YEAR if len(r['summary']['steps']) > 1 else 0):.3g} "
                f"years; reason: {reason}); `{r['driver'].get('command', '?')}`; last lines of its monitor output:",
                "", "```", *r["tail"], "```", ""]
    return "\n".join(out)


def performance_text(results):
    lines = []
    for r in results:
        lines.append(f"- `{os.path.basename(r['dir'])}`: " + where_time_goes(r))
    return "\n".join(lines)


# end-to-end targets at paper size, 2 ranks, MUMPS: (wall s, Newton iterations)
TARGETS = {"wuxi": (25.0, 35), "queretaro_calibrated": (90.0, 60), "queretaro": (180.0, None)}


# the contact solver before one semismooth Newton (an active-set loop around SNES, git 941a8d1), paper size,
# 2 ranks, MUMPS: Newton iterations, factorisations, end-to-end wall s, max opening and slip (cm, face average)
BEFORE = {"wuxi": (71, 53, 53.8, 14.2, 0.272), "queretaro_calibrated": (72, 24, 150.8, 0.822, 5.32),
          "queretaro": (None, None, 387.7, 3.94, 159.0)}


def solver_history(results):
    """The paper cases before and with the one-Newton contact solver, from the runs here."""
    lines = ["| scene | before: Newton / LU / wall | now: Newton (worst step) / LU / Krylov / wall | sub-steps | "
             "max opening before → now | max slip before → now |", "|---|---|---|---|---|---|"]
    for case, (n0, lu0, w0, o0, s0) in BEFORE.items():
        r = _default_run(results, case)
        if r is None:
            continue
        steps = r["summary"]["steps"]
        wall = (r["driver"] or {}).get("wall_end_to_end_s") or r["summary"]["wall_s"]["total"]
        lu = sum(st.get("factorizations", 0) for st in steps)
        worst = max((st.get("newton_its", 0) for st in steps), default=0)
        lines.append(f"| `{case}` | {n0 if n0 is not None else '—'} / {lu0 if lu0 is not None else '—'} / {w0:.1f} s"
                     f" | {r['newton_total']} ({worst}) / {lu} / {r['ksp_total']} / {wall:.1f} s | "
                     f"{r['substeps_total'] or 'none'} | {o0:.3g} → {100 * r['max_fault_opening_m']:.3g} cm | "
                     f"{s0:.3g} → {100 * r['max_fault_slip_m']:.3g} cm |")
    return "\n".join(lines)


SOLVER_NOTES = (
    "The maxima moved with the discretisation, not with the solver. The \"before\" column was measured with the "
    "traction-jump stabilisation on another machine (AMD EPYC); \"now\" has the face bubbles that replaced it "
    "(docs/theory.md, \"Face bubbles\"): a closed face has no opening and a stuck face no slip increment to the "
    "solver's tolerance, and the maxima are over the open and the slid faces (summary.json). Calibrated "
    "Queretaro's fault answer is a discretisation band, not physics: at its load the fault neither slides nor opens "
    "in the continuum, and the slip and opening each mesh reports sit in its top rows of faces under the land "
    "surface (and, on the paper's 52 m wide elements, in the load P1 hangs on the fault); they vanish under "
    "refinement (at half the paper's size the slip potency falls from 4,308 to 1,021 m^3; on the plane-strain "
    "section the open zone is the top row of faces from 8 m to 0.25 m and its integrals fall as h^1.6; "
    "docs/verification.md, \"calibrated Queretaro\" and \"Queretaro's fault in plane strain\"). Wuxi's fully "
    "open fissure is unaffected.")


def targets_text(results):
    """The targets of the one-Newton contact solver (2 ranks, end to end), and where the time goes: the
    factorisations, counted and timed by PETSc's log (MatLUFactorNum)."""
    out = []
    for case, (target, its) in TARGETS.items():
        r = _default_run(results, case)
        if r is None:
            continue
        wall = (r["driver"] or {}).get("wall_end_to_end_s") or r["summary"]["wall_s"]["total"]
        steps = r["summary"]["steps"]
        newton = sum(st.get("newton_its", 0) for st in steps)
        worst = max((st.get("newton_its", 0) for st in steps), default=0)
        ok = wall <= target and r["converged"] and (its is None or newton <= its)
        lu_n, lu_t = r["events"].get("Solve", {}).get("MatLUFactorNum", (0, 0.0))
        cost = (f"; the solve stage's {lu_n} factorisations took {lu_t:.0f} s ({lu_t / lu_n:.2f} s each)"
                if lu_n else "")
        out.append(f"- `{case}`: {wall:.0f} s end to end against {target:.0f} s"
                   + (f" and {newton} Newton iterations against {its}" if its else f", {newton} Newton iterations")
                   + f" (at most {worst} in a step): {'met' if ok else 'not met'}{cost}.")
    out.append("")
    out.append(
        "A Newton iteration in which many faces changed state costs one MUMPS factorisation of the "
        "saddle-point Jacobian (PORD ordering: the best of PORD, AMF, AMD and QAMD with Debian's MUMPS, which "
        "has no METIS; BLR gives no gain); one in which no face or only a few changed state since the last "
        "factorisation keeps the factors, as flexible GMRES's preconditioner, while that costs less than a new "
        "factorisation (README, \"Faults and fissures\"; both costs are timed in the run). The run time is then "
        "the number of Newton iterations that change many states times the factorisation's cost: the slipping "
        "patch of a Queretaro scene grows in every step, and each step takes 3-6 such iterations to settle it.")
    return "\n".join(out)


def refinement_text(results):
    """Accuracy against cost: the plain runs of a case (default solver, no tag or extra options) at several mesh
    size factors, with each figure's deviation from the finest run."""
    out = []
    groups = {}
    for r in results:
        d = r["driver"] or {}
        if d.get("solver", "mumps") != "mumps" or not r["converged"] or (d.get("extra") and not d.get("tag")):
            continue
        groups.setdefault((_case_of(r), d.get("tag", "")), []).append(r)
    for (case, tag), runs in sorted(groups.items(), key=lambda kv: (list(CASES).index(kv[0][0]), kv[0][1])):
        if len(runs) < 2:
            continue
        runs.sort(key=lambda r: -float(r["driver"].get("size_factor", 1.0)))
        ref = runs[-1]
        flow = ref["max_drawdown_m"] > 0
        keys = [("max_subsidence_m", "subsidence"), ("max_fault_slip_m", "slip"),
                ("max_fault_opening_m", "opening"), ("surface_opening_m", "surface opening")]
        if flow:
            keys.append(("max_drawdown_m", "drawdown"))
        head = ("| size factor | nodes | dofs | end to end s | LU | " + " | ".join(f"max {lab}" for _, lab in keys) + " |")
        lines = [f"`{case + ('-' + tag if tag else '')}` (deviations from the finest run, size factor "
                 f"{float(ref['driver'].get('size_factor', 1.0)):g}):", "", head,
                 "|" + "---|" * (head.count("|") - 1)]
        for r in runs:
            cells = []
            for key, _ in keys:
                v, v0 = r.get(key) or 0.0, ref.get(key) or 0.0
                dev = "" if r is ref or not v0 else f" ({100.0 * (v - v0) / v0:+.1f} %)"
                cells.append(f"{_m(v, 'cm') if 'opening' in key or 'slip' in key else _m(v)}{dev}")
            lu = sum(st.get("factorizations", 0) for st in r["summary"]["steps"])
            lines.append(f"| {float(r['driver'].get('size_factor', 1.0)):g} | {r['summary']['mesh']['nodes']:,} | "
                         f"{r['summary']['dofs']:,} | {_s(r['driver'].get('wall_end_to_end_s'))} | {lu} | "
                         + " | ".join(cells) + " |")
        prev = runs[-2]
        moving = []
        for key, lab in keys:
            v, v0 = prev.get(key) or 0.0, ref.get(key) or 0.0
            if v0 and abs(v - v0) > 0.1 * abs(v0):
                moving.append(f"{lab} {100.0 * (v0 - v) / v:+.0f} %")
        f1, f0 = float(prev["driver"].get("size_factor", 1.0)), float(ref["driver"].get("size_factor", 1.0))
        lines += ["", (f"From size factor {f1:g} to {f0:g} " + (
            "these maxima change by more than 10 %, so they are not mesh-converged: " + ", ".join(moving) + "."
            if moving else "every maximum above changes by less than 10 %."))]
        out += lines + [""]
    return "\n".join(out)


def write_readme(results, path, regenerate_cmd):
    results = sorted(results, key=lambda r: (list(CASES).index(_case_of(r)), os.path.basename(r["dir"])))
    d0 = next((r["driver"] for r in results if r["driver"]), {})
    ver = {}
    revs = {}                   # pfault git revision -> runs made with it
    for r in results:
        vpath = os.path.join(r["dir"], "versions.json")
        if os.path.exists(vpath):
            with open(vpath) as fh:
                v = json.load(fh)
            ver = ver or v
            revs.setdefault(v.get("git", "?"), []).append(os.path.basename(r["dir"]))
    if len(revs) > 1:
        main_rev = max(revs, key=lambda k: len(revs[k]))
        others = "; ".join(f"{', '.join(f'`{n}`' for n in names)} at {rev[:7]}{rev[40:]}"
                           for rev, names in revs.items() if rev != main_rev)
        ver["git"] = f"{main_rev} ({others})"
    text = [
        "# runs",
        "",
        "Output of runs lands here (`runs/<run>/`); only this README is committed. It is written by "
        "`studies/casestudies.py`; regenerate runs, figures and this file with",
        "",
        "```bash",
        regenerate_cmd,
        "```",
        "",
        "`--no-run` rebuilds the figures and this file from the run directories already here; `--cases`, "
        "`--solver iterative`, `--size-factor 3`, `--tag NAME -- -option value ...` make variant runs "
        "(`runs/<case>-<solver|tag>[-f<factor>]`), listed next to the default ones.",
        "",
        "Case studies of Franceschini, Teatini, Janna, Ferronato, Gambolati, Ye and Carreón-Freyre, *Modelling "
        "ground rupture due to groundwater withdrawal: applications to test cases in China and Mexico*, Proc. "
        "IAHS 372, 63-68, 2015. The paper's figures are those stated in its text (nothing digitised from its "
        "plots). pfault's maxima are over the converged steps.",
        "",
        f"Machine: {d0.get('host_cpus', '?')} cores ({d0.get('cpu_model', '?')}), shared with other jobs: the "
        "timing table gives the mean 1-minute load average during each run (2.0: the two ranks had the "
        "machine to themselves; above that, wall times are inflated). PETSc "
        f"{ver.get('petsc', '?')}, petsc4py {ver.get('petsc4py', '?')}, pfault git {ver.get('git', '?')}.",
        "",
        "## Contact solver: before and after one semismooth Newton (paper-size meshes, 2 ranks, MUMPS)",
        "",
        "Before: the active-set loop around SNES (git 941a8d1). Newton counts include each step's elastic trial "
        "when a step takes one; LU counts PETSc's MatLUFactorNum events; Krylov iterations are flexible GMRES's on "
        "the factors (one triangular solve each).",
        "",
        solver_history(results),
        "",
        SOLVER_NOTES,
        "",
        targets_text(results),
        "",
        "## Paper vs pfault (paper-size meshes, 2 ranks, MUMPS)",
        "",
        summary_table(results),
        "",
    ]
    for case in CASES:
        runs = [r for r in results if _case_of(r) == case and float(r["driver"].get("size_factor", 1.0)) == 1.0]
        if not runs:
            continue
        text += [f"## {case}", ""]
        for r in runs:
            text += [f"- `{os.path.basename(r['dir'])}`: `{r['driver'].get('command', '?')}` (exit code "
                     f"{r['driver'].get('exit_code', '?')})"]
        text += ["", results_table(runs, case), ""]
        for r in runs:
            figs = [f for f in figures.FIGURES if os.path.exists(os.path.join(r["dir"], f))]
            text += [f"Figures of `{os.path.basename(r['dir'])}` (in `{r['dir']}/`, not committed): "
                     + ", ".join(f"`{f}`" for f in figs) + ".", ""]
            text += [f"<details><summary>{os.path.basename(r['dir'])}: per step Newton/Krylov iterations, "
                     "sub-steps, fault states</summary>", "", steps_table(r), "", "</details>", ""]
    text += ["## Differences from the paper", "", discussion(results), ""]
    conv = convergence_text(results)
    text += ["## Convergence at paper size", "", conv or "Every run listed here converged.", "", CONVERGENCE_NOTE, ""]
    text += ["## Wall times by stage", "",
             "From summary.json (`wall_s`): mesh = gmsh meshing on rank 0 + distribution, setup = fields, "
             "assembly, solver objects and the first factorisation (a geostatic fault scene's first one is its "
             "gravity solve's, in solve), solve = the geostatic state and all time steps, output = XDMF/HDF5. "
             "End to end = the mpirun process as timed by the driver (adds MPI start-up and imports). CPU s / rank "
             "= user+system CPU of all processes divided by the ranks: close to what the wall time would be on an "
             "idle machine when the load is above 2.", "",
             timing_table(results), "", "Where the time goes (`-log_view`, in `runs/<run>/log_view.txt`):", "",
             performance_text(results), ""]
    refine = refinement_text(results)
    if refine:
        text += ["## Accuracy against cost (mesh size factor)", "",
                 "The same scenes on coarser (size factor > 1) and finer (< 1) meshes of the same geometry, 2 ranks. "
                 "The drawdown of a flow scene peaks at the well nodes and grows like ln(1/h) there, so it changes "
                 "with the mesh too.", "", refine]
    with open(path, "w") as fh:
        fh.write("\n".join(text))
    return path


def all_results(runs_dir):
    out = []
    root = os.path.join(REPO, runs_dir) if not os.path.isabs(runs_dir) else runs_dir
    for name in sorted(os.listdir(root)) if os.path.isdir(root) else []:
        base = name.split("-")[0]
        if base not in CASES:
            continue
        r = collect(os.path.join(root, name))
        if r is not None:
            r["dir"] = os.path.join(runs_dir, name)
            out.append(r)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.casestudies", description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ", ".join(CASES))
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--solver", default="mumps", help="a -pfault_solver NAME (default mumps)")
    ap.add_argument("--size-factor", type=float, default=1.0, help="mesh size factor (default 1: paper size)")
    ap.add_argument("--no-run", action="store_true", help="only figures and README from existing runs")
    ap.add_argument("--no-readme", action="store_true", help="do not rewrite runs/README.md")
    ap.add_argument("--tag", default="", help="name suffix of a variant run made with extra options")
    ap.add_argument("--runs-dir", default="runs")
    ap.add_argument("--timeout", type=float, default=7200.0, help="per run (s)")
    ap.add_argument("extra", nargs=argparse.REMAINDER, help="after --: more pfault/PETSc options for every run")
    args = ap.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    for c in cases:
        if c not in CASES:
            ap.error(f"unknown case '{c}' (known: {', '.join(CASES)})")
    extra = [a for a in args.extra if a != "--"]
    os.chdir(REPO)
    status = 0
    for c in cases:
        name = run_name(c, args.solver, args.size_factor, args.tag)
        run_dir = os.path.join(args.runs_dir, name)
        if not args.no_run:
            rec = run_case(c, args.ranks, args.solver, args.size_factor, extra, args.timeout, runs_dir=args.runs_dir,
                           tag=args.tag)
            status = status or (rec["exit_code"] != 0)
        if os.path.exists(os.path.join(run_dir, "summary.json")):
            for p in figures.make_figures(run_dir):
                print(f"case studies: wrote {p}", flush=True)
    if not args.no_readme:
        path = write_readme(all_results(args.runs_dir), os.path.join(args.runs_dir, "README.md"),
                            ".venv/bin/python benchmarks/case_studies.py   # Wuxi ~50 s, calibrated Queretaro ~2.5 min; "
                            "the stated-rate Queretaro is slower")
        print(f"case studies: wrote {path}", flush=True)
    return int(status)


if __name__ == "__main__":
    sys.exit(main())
