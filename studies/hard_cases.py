"""Hard cases for the contact solver: small scenes that stress the semismooth Newton, each run with the scene's
defaults (no -snes_*, -ksp_* or -pfault_time_max_cuts option) and checked against one invariant.

    .venv/bin/python benchmarks/hard_cases.py [--quick] [--cases NAME,...] [--no-run] [--runs-dir DIR]

Every case runs as ``mpirun -n RANKS python -m pfault SCENE [options] -pfault_output_dir DIR/<case>
-pfault_contact_monitor`` (one at a time: the reference machine has 2 cores), its stdout in
``DIR/<case>/stdout.txt`` and the driver's record (command, exit code, end-to-end wall time) in
``DIR/<case>/hardcase.json``. Then ``DIR/report.md`` (one row per case: converged in every step, Newton
iterations in all and in the worst step, sub-steps, wall time, the invariant and its value; the command and
the contact monitor's lines for every case that failed or was cut into sub-steps) and
``DIR/newton_per_step.png`` are written. DIR is ``runs/hard_cases``. The exit code is 1 when a case did not
converge or its invariant failed, 0 otherwise.

``--quick`` runs the cases marked quick (one per kind of difficulty, all on box meshes; some with fewer time steps,
``quick_options``, which the report's table shows: the scenes are loaded proportionally, so their final state is the
same) and is what the test suite runs (tests/verification/test_hard_cases.py: 11 runs, 82-177 s under a load
average of 15 from other jobs on the 2-core reference machine, 55 CPU seconds); ``--cases`` runs the named ones; either adds the runs their invariants compare with.
``--no-run`` rebuilds the report from the run directories already there. The runs draw no PNG figures.

The scenes are the two-blocks scene (config/two_blocks.opts, analytic stick/slip), its horizontal version
with two materials (config/hard/two_layers.opts), an earth fissure at a basin margin
(config/hard/fissure_box.opts), two faults near a basin corner (config/hard/two_faults.opts), and Wuxi and
the calibrated Queretaro at mesh size factor 3.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from pfault.post import rundir
from pfault.post.rundir import read_summary
from pfault.units import YEAR

from pfault.tools.runs import command, cpu_model, run_logged, shown

from . import REPO

RUNS_DIR = os.path.join("runs", "hard_cases")
EXIT_OK, EXIT_FAILED = 0, 1

# two-blocks scene (config/two_blocks.opts): E = 10 MPa, nu = 0.25, p = 1 MPa, L = 2 m, delta = 0.5 m
P = 1.0e6
G = 10.0e6 / (2 * 1.25)
L_BLOCKS = 2.0
SZZ = -P / 3.0                      # sigma_zz of the uniform state (nu = 0.25)
TWO_BLOCKS = "config/two_blocks.opts"
TWO_LAYERS = "config/hard/two_layers.opts"
FISSURE = "config/hard/fissure_box.opts"
TWO_FAULTS = "config/hard/two_faults.opts"
FISSURE_FINE = ("-pfault_box_cells", "32,16,20")
FAULTS_DEEP = ("-pfault_box_fault_planes", "fa:x:175:0:150:-100:0,fb:y:175:0:150:-100:0")
# E/h of the fissure box's softer top material (clay, 8 MPa) on its fault faces (h = sqrt(face area), the
# size pfault's default penalty uses): 12.5 m x 10 m halves, and 6.25 m x 5 m halves at h/2
E_OVER_H = 8.0e6 / math.sqrt(62.5)
E_OVER_H_FINE = 8.0e6 / math.sqrt(15.625)
# --quick runs the 10-step fissure box and two-faults scenes in 2 steps (their loading is proportional and their
# faults cohesionless: the same final state), each case and the cases it compares with alike
QUICK_STEPS = ("-pfault_time_steps", "2")


# ------------------------------------------------------------------------------------------------------
# cases
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Verdict:
    value: float | None     # the invariant's figure (None: could not be evaluated)
    ok: bool
    note: str = ""


@dataclass(frozen=True)
class Invariant:
    what: str               # what is compared, for the table
    bound: str              # the pass condition, for the table
    evaluate: Callable      # (RunResult, {name: RunResult}) -> Verdict
    needs: tuple = ()       # cases whose runs it compares with


@dataclass(frozen=True)
class Case:
    name: str
    kind: str               # the difficulty it stresses
    scene: str
    invariant: Invariant
    options: tuple = ()
    ranks: int = 2
    quick: bool = False
    quick_options: tuple = ()      # added to the options in --quick (the cases it compares with must add the same)

    def args(self, out):
        return [self.scene, *self.options, "-pfault_output_dir", out, "-pfault_contact_monitor", "-pfault_figures",
                "false"]

    def in_quick_form(self):
        """The case as --quick runs it: its quick_options added, and said in its description."""
        if not self.quick_options:
            return self
        return replace(self, options=self.options + self.quick_options,
                       kind=f"{self.kind} (quick: `{' '.join(self.quick_options)}`)")


@dataclass
class RunResult:
    case: Case
    dir: str
    record: dict
    summary: dict | None
    verdict: Verdict | None = None

    @property
    def steps(self):
        return [] if self.summary is None else [s for s in self.summary["steps"] if not s.get("initial")]

    @property
    def converged(self):
        return (self.record.get("exit_code") == 0 and self.summary is not None and self.summary["converged"]
                and all(s["converged"] for s in self.steps))

    def fault(self, step=-1):
        return rundir.read_fault(self.dir, step)


# ------------------------------------------------------------------------------------------------------
# invariants: each reads the finished runs (fault.xdmf per step, summary.json)
# ------------------------------------------------------------------------------------------------------
def _jumps(res, step=-1):
    """Per fault face: opening and slip vector (m), serial face order."""
    f = res.fault(step).cell_data
    return np.column_stack([f["opening"], f["slip"]])


def _rel(a, b):
    nb = np.linalg.norm(b)
    return float(np.linalg.norm(a - b) / nb) if nb > 0 else float(np.linalg.norm(a))


def converges():
    """No invariant beyond convergence (a reference run, or a scene that has to be accepted first)."""
    return Invariant("every step converges", "-", lambda res, runs: Verdict(None, True))


def analytic_slip(exact, scale=None, tol=1e-6):
    """Every face slips by ``exact`` (0: sticks) without opening: max |slip - exact|, |opening| over scale."""
    scale = scale or exact

    def evaluate(res, runs):
        f = res.fault().cell_data
        err = max(np.max(np.abs(f["slip_magnitude"] - exact)), np.max(np.abs(f["opening"])))
        return Verdict(err / scale, err / scale <= tol, f"mean slip {np.mean(f['slip_magnitude']):.7g} m")
    what = (f"slip = analytic {exact:.7g} m, no opening" if exact > 0 else "stick: no slip, no opening")
    return Invariant(f"{what} (max error / {scale:g} m)", f"<= {tol:g}", evaluate)


def cycle_opening(tol=1e-6):
    """Two-blocks cycle (CYCLE): pulled, every face open with the opening = the pull; pushed, every face stuck."""
    def evaluate(res, runs):
        n = res.summary["mesh"]["fault_faces"]
        errs, wrong = [], []
        for st in res.steps:
            pull = CYCLE_SCALE[round(st["time_s"], 6)] * 1e-3
            if pull > 0:
                errs.append(abs(st["max_fault_opening_m"] - pull) / pull)
                if st["open"] != n:
                    wrong.append(f"t = {st['time_s']:g}: {st['open']}/{n} open")
            elif st["stick"] != n:
                wrong.append(f"t = {st['time_s']:g}: {st['stick']}/{n} stuck")
        value = max(errs) if errs else None
        ok = value is not None and value <= tol and not wrong and len(res.steps) == len(CYCLE_SCALE)
        return Verdict(value, ok, "; ".join(wrong))
    return Invariant("pulled: all open, opening = pull (max error / pull); pushed: all stuck", f"<= {tol:g}",
                     evaluate)


def cohesive_cycle(tensile_strength, tol=1e-6):
    """Two-blocks cycle (CYCLE) with cohesion: pulled, every face open and carrying the tensile strength
    T = c / tan(phi) (the apex of its Mohr-Coulomb cone, pfault.faults.contact.tensile_strength), so opened by
    less than the pull; pushed, every face stuck. Value: the largest relative error of the open faces' effective
    normal traction against T at the last step (pulled)."""
    def evaluate(res, runs):
        n = res.summary["mesh"]["fault_faces"]
        wrong = []
        for st in res.steps:
            pull = CYCLE_SCALE[round(st["time_s"], 6)] * 1e-3
            if pull > 0 and (st["open"] != n or not 0.0 < st["max_fault_opening_m"] < pull):
                wrong.append(f"t = {st['time_s']:g}: {st['open']}/{n} open, opening {st['max_fault_opening_m']:g}")
            elif pull <= 0 and st["stick"] != n:
                wrong.append(f"t = {st['time_s']:g}: {st['stick']}/{n} stuck")
        tn = res.fault().cell_data["traction_normal_effective"]
        value = float(np.max(np.abs(tn - tensile_strength)) / tensile_strength)
        ok = value <= tol and not wrong and len(res.steps) == len(CYCLE_SCALE)
        return Verdict(value, ok, "; ".join(wrong))
    return Invariant("pulled: all open at the tensile strength c/tan(phi) (max error / T); pushed: all stuck",
                     f"<= {tol:g}", evaluate)


def path_independence(ref, tol=1e-6):
    """Proportional loading: the final opening and slip fields equal those of run ``ref`` (relative 2-norm)."""
    def evaluate(res, runs):
        a, b = _jumps(res), _jumps(runs[ref])
        states = int(np.sum(res.fault().cell_data["state"] != runs[ref].fault().cell_data["state"]))
        return Verdict(_rel(a, b), _rel(a, b) <= tol, f"{states} faces in another state")
    return Invariant(f"final opening/slip fields vs `{ref}` (relative difference)", f"<= {tol:g}", evaluate, (ref,))


def reopening(t_open, t_closed, t_reopen, tol=0.05, closed_share=0.2):
    """Load cycle (times in years): the fissure open at t_open closes at t_closed (at most ``closed_share`` of the
    open faces stay open) and reopens at t_reopen to the opening field of t_open (relative difference)."""
    def evaluate(res, runs):
        snaps = {}
        for k in range(res.fault().num_steps):
            snap = res.fault(k)
            snaps[round(snap.time / YEAR, 6)] = snap.cell_data
        a, b, c = (snaps.get(float(t)) for t in (t_open, t_closed, t_reopen))
        if a is None or b is None or c is None:
            return Verdict(None, False, "output times missing")
        n_open = [int(np.sum(x["state"] == 2)) for x in (a, b, c)]
        value = _rel(c["opening"], a["opening"])
        ok = value <= tol and n_open[0] > 0 and n_open[1] <= closed_share * n_open[0]
        return Verdict(value, ok, f"open faces {n_open[0]} -> {n_open[1]} -> {n_open[2]}; max opening "
                       f"{a['opening'].max() * 100:.3g} -> {b['opening'].max() * 100:.3g} -> "
                       f"{c['opening'].max() * 100:.3g} cm")
    return Invariant(f"opening at {t_reopen} yr vs {t_open} yr (relative difference); at {t_closed} yr at most "
                     f"{closed_share:.0%} of the faces still open", f"<= {tol:g}", evaluate)


def _swap_pairs(cen, fid, other_cen=None, other_fid=None, first=0, second=1):
    """Faces of fault ``first`` and their images under x <-> y on fault ``second`` (index arrays), matched by
    centroid; the images among the faces of another run (``other_cen``, ``other_fid``) when given."""
    other_cen = cen if other_cen is None else other_cen
    other_fid = fid if other_fid is None else other_fid
    a, b = np.nonzero(fid == first)[0], np.nonzero(other_fid == second)[0]
    ka = a[np.lexsort(np.round(cen[a], 6).T)]
    kb = b[np.lexsort(np.round(other_cen[b][:, [1, 0, 2]], 6).T)]
    if len(ka) != len(kb) or not np.allclose(cen[ka], other_cen[kb][:, [1, 0, 2]]):
        return None
    return ka, kb


def _swap_difference(snap, other, pairs):
    """Largest difference of the swapped face pairs' opening, slip and normal traction over the largest value,
    and the number of pairs in different states."""
    ka, kb = pairs
    errs = []
    for key in ("opening", "slip_magnitude", "traction_normal"):
        v, w = snap.cell_data[key], other.cell_data[key]
        errs.append(np.max(np.abs(v[ka] - w[kb])) / max(np.max(np.abs(v)), 1e-300))
    return max(errs), int(np.sum(snap.cell_data["state"][ka] != other.cell_data["state"][kb]))


def xy_symmetry(tol=1e-8):
    """Two-faults scene: the fields of fault fb are those of fa with x and y swapped."""
    def evaluate(res, runs):
        snap = res.fault()
        pairs = _swap_pairs(snap.points[snap.cells].mean(axis=1), snap.cell_data["fault"])
        if pairs is None:
            return Verdict(None, False, "the faults are not images of each other")
        value, same = _swap_difference(snap, snap, pairs)
        return Verdict(value, value <= tol and same == 0, f"{same} face pairs in different states")
    return Invariant("fault fb = fault fa with x, y swapped (opening, slip, normal traction: max difference / "
                     "max value)", f"<= {tol:g}", evaluate)


def xy_swapped(ref, tol=1e-8):
    """Two-faults scene with the faults' roles swapped in run ``ref`` (fa there as fb here with x, y swapped, and
    fb as fa): each fault's fields are those of the other fault of ``ref`` with x and y swapped."""
    def evaluate(res, runs):
        snap, other = res.fault(), runs[ref].fault()
        cen, fid = snap.points[snap.cells].mean(axis=1), snap.cell_data["fault"]
        ocen, ofid = other.points[other.cells].mean(axis=1), other.cell_data["fault"]
        value, same = 0.0, 0
        for first, second in ((0, 1), (1, 0)):
            pairs = _swap_pairs(cen, fid, ocen, ofid, first, second)
            if pairs is None:
                return Verdict(None, False, f"the faults are not the images of `{ref}`'s")
            v, n = _swap_difference(snap, other, pairs)
            value, same = max(value, v), same + n
        return Verdict(value, value <= tol and same == 0, f"{same} face pairs in different states")
    return Invariant(f"fault fa = fault fb of `{ref}` and fb = its fa, with x, y swapped (opening, slip, normal "
                     "traction: max difference / max value)", f"<= {tol:g}", evaluate, (ref,))


def both(first, second):
    """Two invariants of one run: the larger of their figures, passed when both pass."""
    def evaluate(res, runs):
        a, b = first.evaluate(res, runs), second.evaluate(res, runs)
        value = None if a.value is None or b.value is None else max(a.value, b.value)
        figures = "/".join("—" if v.value is None else f"{v.value:.3g}" for v in (a, b))
        return Verdict(value, a.ok and b.ok, "; ".join([f"each {figures}"] + [v.note for v in (a, b) if v.note]))
    return Invariant(f"{first.what}; {second.what}", first.bound if first.bound == second.bound
                     else f"{first.bound}; {second.bound}", evaluate, first.needs + second.needs)


def contact_conditions(cohesion, phi, tol=1e-6):
    """The output tractions obey the contact law: no effective tension, |t_T| <= c - tan(phi) t_N,eff, on the
    limit where slipping, traction-free where open (max violation over the largest effective traction)."""
    tan_phi = math.tan(math.radians(phi))

    def evaluate(res, runs):
        f = res.fault().cell_data
        tn, tt, st = f["traction_normal_effective"], np.linalg.norm(f["traction_shear"], axis=1), f["state"]
        limit = cohesion - tan_phi * tn
        closed = st != 2
        viol = np.concatenate([np.maximum(tn[closed], 0.0), np.maximum(tt - limit, 0.0)[closed],
                               np.abs(tt - limit)[st == 1], np.abs(tn[~closed]), tt[~closed], [0.0]])
        scale = max(np.max(np.abs(tn)), 1e-300)
        counts = "/".join(str(int(np.sum(st == k))) for k in range(3))
        return Verdict(viol.max() / scale, viol.max() / scale <= tol, f"stick/slip/open {counts}")
    return Invariant("contact law at the last step (Coulomb cone, slip on it, open traction-free; max violation "
                     "/ max |t_N,eff|)", f"<= {tol:g}", evaluate)


def rank_agreement(ref, tol=1e-8):
    """Partition independence: fault fields equal those of run ``ref`` (another rank count)."""
    def evaluate(res, runs):
        a, b = res.fault().cell_data, runs[ref].fault().cell_data
        value = max(_rel(_jumps(res), _jumps(runs[ref])), _rel(a["traction_normal"], b["traction_normal"]))
        faces = res.summary.get("partition", {}).get("fault_faces")      # summary.json: per rank
        split = faces is not None and sum(1 for n in faces if n > 0) > 1
        note = f"fault faces per rank {faces}" if faces is not None else "fault faces per rank not reported"
        return Verdict(value, value <= tol and split, note)
    return Invariant(f"opening/slip and normal traction vs `{ref}` (relative difference); fault faces on more "
                     f"than one rank", f"<= {tol:g}", evaluate, (ref,))


def penalty_vs_lagrange(ref, softer):
    """Penalty against the Lagrange run ``ref`` while the penalty's own error dominates (k up to 100 E/h): the
    difference of the final opening/slip fields decreases with k (below every softer penalty run that ran)."""
    def evaluate(res, runs):
        value = _rel(_jumps(res), _jumps(runs[ref]))
        prev = [runs[s].verdict.value for s in softer if s in runs and getattr(runs[s], "verdict", None) is not None
                and runs[s].verdict.value is not None]
        note = f"softer k: {', '.join(f'{v:.3g}' for v in prev)}" if prev else ""
        return Verdict(value, all(value < v for v in prev), note)
    return Invariant(f"final opening/slip fields vs Lagrange `{ref}` (relative difference)", "below the softer k",
                     evaluate, (ref, *softer))


# Penalty faces at k -> infinity hold the faces' mean jumps (with the face bubbles' part), as the multipliers do:
# their difference to the Lagrange faces is their own, 1/k (fissure box, benchmarks/penalty_lagrange.py: 2.3e-2,
# 2.4e-4, 2.4e-6 at 100, 1e4, 1e6 E/h). With the former traction-jump stabilisation (S at 1 % of the compliance
# estimate) the Lagrange answer moved by a share proportional to S, 2.4 % at h and 3.3 % at h/2: the bound below
# was that share with a margin, and is kept as the bound beyond 100 E/h.
STABILISATION_GAP = 0.05


def penalty_gap(ref, tol=STABILISATION_GAP):
    """Penalty against the Lagrange run ``ref`` at a high stiffness: the difference of the final opening/slip
    fields at most ``tol``."""
    def evaluate(res, runs):
        value = _rel(_jumps(res), _jumps(runs[ref]))
        return Verdict(value, value <= tol)
    return Invariant(f"final opening/slip fields vs Lagrange `{ref}` (relative difference)", f"<= {tol:g}",
                     evaluate, (ref,))


def penalty_rate_in_k(ref, rungs, ratio, lo=0.9, hi=1.1, gap=STABILISATION_GAP):
    """Penalty error ~ 1/k: with runs at k / ratio^2, k / ratio (``rungs``) and k, the changes of the final
    opening/slip fields between successive runs shrink by ``ratio`` (order log(d1 / d2) / log(ratio) in
    [lo, hi]); and the answer is within ``gap`` of the Lagrange run ``ref``."""
    def evaluate(res, runs):
        a, b, c = _jumps(runs[rungs[0]]), _jumps(runs[rungs[1]]), _jumps(res)
        d1, d2 = float(np.linalg.norm(b - a)), float(np.linalg.norm(c - b))
        order = math.log(d1 / d2) / math.log(ratio) if d1 > 0 and d2 > 0 else None
        to_lagrange = _rel(c, _jumps(runs[ref]))
        ok = order is not None and lo <= order <= hi and to_lagrange <= gap
        return Verdict(order, ok, f"changes {d1 / np.linalg.norm(c):.3g}, {d2 / np.linalg.norm(c):.3g}; "
                       f"vs Lagrange {to_lagrange:.3g}")
    return Invariant(f"order in k of the final opening/slip fields (changes from `{rungs[0]}` to `{rungs[1]}` to "
                     f"this run); and vs Lagrange `{ref}` (relative difference)", f"{lo:g} to {hi:g}; <= {gap:g}",
                     evaluate, (ref, *rungs))


def _opt(*pairs):
    return tuple(str(a) for a in pairs)


def two_blocks_shear(phi, delta):
    """Two-blocks options for friction angle phi and shear displacement delta, with the top and bottom
    tractions of the uniform state it ends in; returns (options, exact slip)."""
    tau_l = P * math.tan(math.radians(phi))
    tau = min(G * delta / L_BLOCKS, tau_l)
    opts = _opt("-pfault_box_cells", "8,4,4", "-pfault_fault_fault_friction_angle", f"{phi:g}",
                "-pfault_bc_xmax_displacement", f"0,0,{delta!r}",
                "-pfault_bc_top_traction", f"{tau!r},0,{SZZ!r}", "-pfault_bc_bottom_traction", f"{-tau!r},0,{-SZZ!r}")
    return opts, max(0.0, delta - L_BLOCKS * tau_l / G)


# right face of the two blocks pushed in by 0.5 and 1 mm, pulled out by 4.5 and 10 mm, pushed, pulled (no shear)
CYCLE_SCALE = {0.5: -0.5, 1.0: -1.0, 1.5: 4.5, 2.0: 10.0, 2.5: 4.5, 3.0: -1.0, 3.5: 4.5, 4.0: 10.0}
CYCLE = _opt("-pfault_box_cells", "8,4,4", "-pfault_bc_xmax_components", "x,z", "-pfault_bc_xmax_displacement",
             "1e-3,0,0", "-pfault_bc_xmax_traction", "0,0,0", "-pfault_bc_top_traction", "0,0,0",
             "-pfault_bc_bottom_traction", "0,0,0", "-pfault_bc_xmax_history", "0:0,1:-1,2:10,3:-1,4:10",
             "-pfault_time_end", "4", "-pfault_time_steps", "8")
WUXI_CYCLE = _opt("-pfault_mesh_size_factor", "3",
                  "-pfault_material_sand_head_drawdown", "0:0,10*year:20,20*year:0,30*year:20",
                  "-pfault_material_clay_head_drawdown", "0:0,10*year:10,20*year:0,30*year:10",
                  "-pfault_time_end", "30*year", "-pfault_time_steps", "15")


def penalty(fault, k):
    return _opt(f"-pfault_fault_{fault}_method", "penalty", f"-pfault_fault_{fault}_penalty_normal", f"{k:.6g}",
                f"-pfault_fault_{fault}_penalty_tangential", f"{k:.6g}")


def cases():
    """Every case of the study, in report order."""
    out = []
    layers = {"stiff_below": "lower", "stiff_above": "upper"}
    for name, stiff in layers.items():
        exact = 0.5 - P * math.tan(math.radians(30.0)) * (1.0 / G + 1.0 / (G * 1e5))
        out.append(Case(f"contrast_1e5_{name}", f"E 1e5 times larger {name.split('_')[1]} the fault (on its "
                        f"{'minus' if stiff == 'lower' else 'plus'} side)", TWO_LAYERS,
                        analytic_slip(exact),
                        _opt("-pfault_box_cells", "4,4,8", f"-pfault_material_{stiff}_young_modulus", "1e12"),
                        quick=stiff == "lower"))
    for phi in (1, 15, 45, 60):
        opts, exact = two_blocks_shear(phi, 0.6)
        out.append(Case(f"friction_{phi}", f"friction angle {phi} deg ({'stick' if exact == 0 else 'slip'})",
                        TWO_BLOCKS, analytic_slip(exact, scale=0.6), opts, quick=phi == 1))
    # the pulls of CYCLE stretch the glued blocks by up to ~55 kPa: c = 10 kPa opens them at 17 kPa
    out.append(Case("cohesion_cutoff", "c = 10 kPa: pushed, pulled, pushed, pulled; the faces open at the apex of "
                    "the cone, c/tan(phi) = 17 kPa of tension, and carry it while open", TWO_BLOCKS,
                    cohesive_cycle(1e4 / np.tan(np.radians(30.0))), CYCLE + _opt("-pfault_fault_fault_cohesion", "1e4"),
                    quick=True))
    out += _step_cases()
    out.append(Case("cycle_two_blocks", "pressed, pulled open, pressed shut, reopened (c = 0)", TWO_BLOCKS,
                    cycle_opening(), CYCLE))
    out.append(Case("cycle_wuxi_f3", "Wuxi (size factor 3): 10 yr drawdown, 10 yr recovery, 10 yr drawdown",
                    "config/wuxi_recovery_elastic.opts", reopening(10, 20, 30), WUXI_CYCLE))
    out.append(Case("faults_to_fixed_bottom", "two faults through the whole depth: reach the fixed bottom, the "
                    "rollers and the land surface", TWO_FAULTS, xy_symmetry(), FAULTS_DEEP, quick=True,
                    quick_options=QUICK_STEPS))
    out.append(Case("zero_strength_fissure", "fissure box: no geostatic stress, c = 0 (stick, slip and open "
                    "faces)", FISSURE, contact_conditions(0.0, 30.0), quick=True, quick_options=QUICK_STEPS))
    out.append(Case("zero_strength_queretaro_f3", "calibrated Queretaro (size factor 3, flow) without "
                    "geostatic stress", "config/queretaro_calibrated.opts", contact_conditions(0.0, 30.0),
                    _opt("-pfault_mesh_size_factor", "3", "-pfault_geostatic", "false")))
    out += _penalty_cases()
    out += _mesh_cases()
    out += _junction_cases()
    out.append(Case("partition_1_rank", "`faults_to_fixed_bottom` on 1 rank (reference)", TWO_FAULTS, converges(),
                    FAULTS_DEEP, ranks=1))
    out.append(Case("partition_3_ranks", "`faults_to_fixed_bottom` on 3 ranks (oversubscribed), both faults "
                    "split between ranks", TWO_FAULTS, rank_agreement("partition_1_rank"), FAULTS_DEEP, ranks=3))
    return out


def _step_cases():
    steps = [Case("proportional_1_step", "fissure box, the 10-year drawdown in 1 step", FISSURE, converges(),
                  _opt("-pfault_time_steps", "1"), quick=True),
             Case("proportional_4_steps", "fissure box, the same in 4 steps", FISSURE,
                  path_independence("proportional_1_step"), _opt("-pfault_time_steps", "4"), quick=True),
             Case("proportional_40_steps", "fissure box, the same in 40 steps", FISSURE,
                  path_independence("proportional_1_step"), _opt("-pfault_time_steps", "40")),
             Case("proportional_1_step_h2", "fissure box at h/2 (61,440 tets), 1 step", FISSURE, converges(),
                  FISSURE_FINE + _opt("-pfault_time_steps", "1")),
             Case("proportional_10_steps_h2", "fissure box at h/2, 10 steps", FISSURE,
                  path_independence("proportional_1_step_h2"), FISSURE_FINE)]
    return steps


def _penalty_cases():
    out = []
    name = "penalty_{:g}_E_over_h".format
    lagrange = "zero_strength_fissure"
    for m in (1e-2, 1.0, 1e2):
        out.append(Case(name(m), f"fissure box, penalty k = {m:g} E/h = {m * E_OVER_H:.3g} Pa/m", FISSURE,
                        penalty_vs_lagrange(lagrange, [name(s) for s in (1e-2, 1.0) if s < m]),
                        penalty("fissure", m * E_OVER_H)))
    out.append(Case(name(1e3), f"fissure box, penalty k = 1000 E/h = {1e3 * E_OVER_H:.3g} Pa/m", FISSURE,
                    penalty_gap(lagrange), penalty("fissure", 1e3 * E_OVER_H), quick=True, quick_options=QUICK_STEPS))
    out.append(Case(name(1e4), f"fissure box, penalty k = 10000 E/h = {1e4 * E_OVER_H:.3g} Pa/m", FISSURE,
                    penalty_rate_in_k(lagrange, (name(1e2), name(1e3)), 10.0), penalty("fissure", 1e4 * E_OVER_H)))
    out.append(Case("penalty_100_E_over_h_h2", f"fissure box at h/2, penalty k = 100 E/h = "
                    f"{100 * E_OVER_H_FINE:.3g} Pa/m", FISSURE, penalty_gap("proportional_10_steps_h2"),
                    FISSURE_FINE + penalty("fissure", 100 * E_OVER_H_FINE)))
    return out


def _mesh_cases():
    exact = 0.5 - L_BLOCKS * P * math.tan(math.radians(30.0)) / G
    return [Case("sliver_1mm", "tetrahedra 1 mm thick (aspect 500) under the fault: layer interface 1 mm below it",
                 TWO_LAYERS, analytic_slip(exact), _opt("-pfault_box_interfaces", "1.001"), quick=True),
            Case("sliver_10um", "the same 10 micrometres thick (aspect 50,000)", TWO_LAYERS, analytic_slip(exact),
                 _opt("-pfault_box_interfaces", "1.00001")),
            Case("anisotropic_flat", "two blocks, cells 64x2x2: slabs 16 times thinner across the fault than "
                 "along it", TWO_BLOCKS, analytic_slip(exact), _opt("-pfault_box_cells", "64,2,2")),
            Case("anisotropic_long", "two blocks, cells 2x16x16: needles 16 times longer across the fault",
                 TWO_BLOCKS, analytic_slip(exact), _opt("-pfault_box_cells", "2,16,16"))]


CROSSING = ("-pfault_box_fault_planes", "fa:x:175:0:200:-40:0,fb:y:175:0:200:-40:0")
T_JUNCTION = ("-pfault_box_fault_planes", "fa:x:175:0:200:-40:0,fb:y:175:0:175:-40:0")
T_JUNCTION_SWAPPED = ("-pfault_box_fault_planes", "fa:x:175:0:175:-40:0,fb:y:175:0:200:-40:0")


def _junction_cases():
    return [Case("two_faults_apart", "two faults ending one cell (25 m) apart at a basin corner", TWO_FAULTS,
                 xy_symmetry()),
            Case("two_faults_crossing_1_rank", "`two_faults_crossing` on 1 rank (reference)", TWO_FAULTS,
                 converges(), CROSSING, ranks=1, quick=True, quick_options=QUICK_STEPS),
            Case("two_faults_crossing", "two fault planes crossing (X junction: 4 pieces at each junction vertex)",
                 TWO_FAULTS, both(xy_symmetry(), rank_agreement("two_faults_crossing_1_rank")), CROSSING,
                 quick=True, quick_options=QUICK_STEPS),
            Case("two_faults_t_junction_swapped", "`two_faults_t_junction` with the faults' roles swapped: fb "
                 "through, fa ending on it (reference)", TWO_FAULTS, converges(), T_JUNCTION_SWAPPED),
            Case("two_faults_t_junction", "fb ending on fa (T junction: 3 pieces at each junction vertex)",
                 TWO_FAULTS, xy_swapped("two_faults_t_junction_swapped"), T_JUNCTION)]


def select(all_cases, quick=False, names=None):
    """The cases to run: all, the quick ones or the named ones, plus the runs their invariants compare with
    (in report order); the quick ones each in its quick form (Case.in_quick_form)."""
    by_name = {c.name: c for c in all_cases}
    if names:
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise SystemExit(f"hard cases: unknown case(s) {', '.join(unknown)}; known: {', '.join(by_name)}")
        want = set(names)
    else:
        want = {c.name for c in all_cases if c.quick or not quick}
    todo = list(want)
    while todo:
        for dep in by_name[todo.pop()].invariant.needs:
            if dep not in want:
                want.add(dep)
                todo.append(dep)
    chosen = [c for c in all_cases if c.name in want]
    if not quick or names:          # named cases run as they are
        return chosen
    for c in chosen:        # a quick form compares with runs made as it is
        differ = [d for d in c.invariant.needs if by_name[d].quick_options != c.quick_options]
        if differ:
            raise SystemExit(f"hard cases: {c.name} has quick options {c.quick_options} but {', '.join(differ)} "
                             "another: give them the same")
    return [c.in_quick_form() for c in chosen]


# ------------------------------------------------------------------------------------------------------
# running
# ------------------------------------------------------------------------------------------------------
def run_case(case, runs_dir, timeout=1800.0):
    """Runs one case under mpirun from the repository root; returns the driver record (also written to
    <runs_dir>/<case>/hardcase.json)."""
    out = os.path.join(runs_dir, case.name)
    os.makedirs(os.path.join(REPO, out), exist_ok=True)
    for stale in ("summary.json", "hardcase.json"):
        if os.path.exists(os.path.join(REPO, out, stale)):
            os.remove(os.path.join(REPO, out, stale))
    args = ["-m", "pfault", *case.args(out)]
    print(f"hard cases: {case.name}: {shown(command(args, case.ranks))}", flush=True)
    done = run_logged(args, case.ranks, os.path.join(REPO, out, "stdout.txt"), timeout, cwd=REPO)
    rc = "timeout" if done.timed_out else done.code
    rec = {"case": case.name, "command": done.command, "ranks": case.ranks, "exit_code": rc,
           "wall_end_to_end_s": done.wall, "load_avg_1min_after": os.getloadavg()[0],
           "date": time.strftime("%Y-%m-%d %H:%M")}
    with open(os.path.join(REPO, out, "hardcase.json"), "w") as fh:
        json.dump(rec, fh, indent=2)
    print(f"hard cases: {case.name}: exit {rc} in {rec['wall_end_to_end_s']:.1f} s", flush=True)
    return rec


def load(case, runs_dir):
    """The finished run of a case (None if it has no driver record)."""
    out = os.path.join(REPO, runs_dir, case.name)
    path = os.path.join(out, "hardcase.json")
    if not os.path.exists(path):
        return None
    with open(path) as fh:
        rec = json.load(fh)
    return RunResult(case, out, rec, read_summary(out))


def evaluate(results):
    """Each run's invariant (in report order: a penalty row reads the softer rows' verdicts)."""
    for res in results.values():
        missing = [n for n in res.case.invariant.needs if n not in results or results[n].summary is None]
        if res.summary is None or missing:
            res.verdict = Verdict(None, False, "no result" + (f" for {', '.join(missing)}" if missing else ""))
            continue
        try:
            res.verdict = res.case.invariant.evaluate(res, results)
        except (OSError, KeyError, ValueError) as exc:
            res.verdict = Verdict(None, False, f"not evaluated: {exc}")


def passed(res):
    return res.converged and res.verdict is not None and res.verdict.ok


# ------------------------------------------------------------------------------------------------------
# report
# ------------------------------------------------------------------------------------------------------
def _fmt(v):
    return "—" if v is None else f"{v:.3g}"


def _substeps(res):
    cut = [s for s in res.steps if s.get("substeps", 1) > 1]
    return "none" if not cut else f"{len(cut)} step(s) cut, up to {max(s['substeps'] for s in cut)}"


def _status(res):
    if res.converged:
        return "yes"
    rc = res.record.get("exit_code")
    if res.summary is None:
        return "input error (exit 1)" if rc == 1 else f"no result (exit {rc})"
    bad = [i for i, s in enumerate(res.steps, start=1) if not s["converged"]]
    return f"**no**: step {bad[0]} (exit {rc})" if bad else f"**no** (exit {rc})"


def table_row(res):
    its = [s["newton_its"] for s in res.steps]
    lu = sum(s.get("factorizations", 0) for s in res.steps)
    v = res.verdict
    ok = "pass" if passed(res) else "**FAIL**"
    inv = res.case.invariant
    value = _fmt(v.value) + (f" ({v.note})" if v.note else "")
    newton = f"{sum(its)} ({max(its)})" if its else "—"
    return (f"| `{res.case.name}` | {res.case.kind} | {res.case.ranks} | {_status(res)} | {newton} | "
            f"{_substeps(res) if its else '—'} | {lu if its else '—'} | {res.record['wall_end_to_end_s']:.1f} | "
            f"{inv.what} | {value} | {inv.bound} | {ok} |")


def monitor_excerpt(res, keep=4):
    """Contact-monitor lines of the first step that failed or was cut (else the last step): the first and last
    ``keep`` lines of each attempt (the full step, then each retry as sub-steps); the error line of a rejected
    scene."""
    path = os.path.join(res.dir, "stdout.txt")
    if not os.path.exists(path):
        return []
    with open(path) as fh:
        lines = [ln.rstrip() for ln in fh if ln.startswith(("step ", "  newton", "  step not converged",
                                                            "pfault: error"))]
    errors = [ln for ln in lines if ln.startswith("pfault: error")]
    if errors:
        return errors
    ends = [i for i, ln in enumerate(lines) if ln.startswith("step ")]
    if not ends:
        return lines[-2 * keep:]
    pick = next((k for k, i in enumerate(ends) if "sub-steps" in lines[i] or "NOT CONVERGED" in lines[i]),
                len(ends) - 1)
    out, attempt = [], []
    for ln in lines[(ends[pick - 1] + 1 if pick else 0):ends[pick]] + ["  step not converged"]:
        if not ln.startswith("  step not converged"):
            attempt.append(ln)
            continue
        if len(attempt) > 2 * keep:
            attempt = attempt[:keep] + [f"  ... {len(attempt) - 2 * keep} lines left out ..."] + attempt[-keep:]
        out += attempt + [ln]
        attempt = []
    return out[:-1] + [lines[ends[pick]]]


def _failure_section(res):
    v = res.verdict
    why = []
    if not res.converged:
        why.append(f"did not converge: {_status(res)}")
    if res.steps and _substeps(res) != "none":
        why.append(f"sub-steps: {_substeps(res)}")
    if v is not None and not v.ok:
        why.append(f"invariant {res.case.invariant.what}: {_fmt(v.value)} against {res.case.invariant.bound}"
                   + (f" ({v.note})" if v.note else ""))
    out = [f"### `{res.case.name}`: {res.case.kind}", "", "- " + "; ".join(why),
           f"- reproduce: `{res.record['command']}`", "", "```", *monitor_excerpt(res), "```", ""]
    return out


def newton_figure(results, path):
    """Newton iterations per step, one line per case that ran (a cross marks a step cut into sub-steps)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ran = [r for r in results.values() if r.steps]
    fig, ax = plt.subplots(figsize=(11, 6.5))
    colors = plt.get_cmap("tab20")
    for i, res in enumerate(ran):
        its = [s["newton_its"] for s in res.steps]
        x = np.arange(1, len(its) + 1)
        style = "-" if i < 20 else "--"
        ax.plot(x, its, style, marker=".", color=colors(i % 20), label=res.case.name, lw=1.2)
        cut = [k for k, s in enumerate(res.steps) if s.get("substeps", 1) > 1 or not s["converged"]]
        if cut:
            ax.plot(x[cut], np.array(its)[cut], "x", color="k", ms=9)
    ax.set_xlabel("time step")
    ax.set_ylabel("Newton iterations (elastic trial included)")
    ax.set_yscale("log")
    ax.set_title("Hard cases: Newton iterations per step (x: step cut into sub-steps or not converged)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _machine():
    return f"{os.cpu_count()} cores ({cpu_model()})"


def _versions(results):
    for res in results.values():
        path = os.path.join(res.dir, "versions.json")
        if os.path.exists(path):
            with open(path) as fh:
                v = json.load(fh)
            return f"PETSc {v.get('petsc')}, petsc4py {v.get('petsc4py')}, pfault git {v.get('git')}"
    return "versions unknown (no run wrote versions.json)"


HOW_TO_READ = """\
How to read the table: *converged* is yes when every time step converged (pfault's exit code 0); *Newton*
is the number of Newton iterations over all steps, each step's elastic trial included, with the worst step in
brackets; *sub-steps* counts the steps that did not converge at once and were retried as 2, 4, 8 sub-steps;
*LU* counts MUMPS factorisations; *wall* is the end-to-end time of the mpirun (start-up and output included).
The invariant is what shows the answer is right: an analytic value, a symmetry of the mesh and the scene,
path independence under proportional loading, agreement between rank counts, or, for penalty faces, the answer
closing on the Lagrange one as k grows, as 1/k (order 1 in k). A row passes when it converged and its
invariant holds. Every case runs with its scene's defaults and `-pfault_contact_monitor`; no solver option is
given."""


def write_report(results, selected, meta, path):
    lines = ["# Hard cases for the contact solver", "",
             f"Written by `studies/hard_cases.py`: `{meta['command']}` ({meta['date']}, "
             f"{meta['wall_s']:.0f} s in all).", "",
             f"Machine: {_machine()}, shared; 1-minute load average {meta['load_before']:.2f} before the study, "
             f"{meta['load_mean']:.2f} on average after each run (2 ranks alone on 2 cores: about 2). "
             f"{_versions(results)}.", "", HOW_TO_READ, ""]
    npass = sum(1 for c in selected if c.name in results and passed(results[c.name]))
    lines += [f"**{npass} of {len(selected)} cases pass.**", "",
              "| case | what it stresses | ranks | converged | Newton (worst step) | sub-steps | LU | wall s | "
              "invariant | value | bound | result |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in selected:
        if c.name in results:
            lines.append(table_row(results[c.name]))
        else:
            lines.append(f"| `{c.name}` | {c.kind} | {c.ranks} | not run | — | — | — | — | {c.invariant.what} | — | "
                         f"{c.invariant.bound} | **FAIL** |")
    flagged = [results[c.name] for c in selected if c.name in results
               and (not passed(results[c.name]) or _substeps(results[c.name]) not in ("none",))]
    lines += ["", "![Newton iterations per step](newton_per_step.png)", "",
              "## Cases that failed or needed sub-steps", ""]
    if not flagged:
        lines += ["None.", ""]
    for res in flagged:
        lines += _failure_section(res)
    with open(path, "w") as fh:
        fh.write("\n".join(lines).rstrip() + "\n")


# ------------------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------------------
def _parser():
    p = argparse.ArgumentParser(prog="benchmarks/hard_cases.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="the cases marked quick in their quick form (11 runs, "
                   "55 CPU seconds; what the test suite runs)")
    p.add_argument("--cases", default="", help="comma-separated case names (default: all)")
    p.add_argument("--no-run", action="store_true", help="report on the runs already in the runs directory")
    p.add_argument("--runs-dir", default=RUNS_DIR, help=f"output directory (default {RUNS_DIR})")
    p.add_argument("--timeout", type=float, default=1800.0, help="seconds per run before it is stopped")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    return p


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    args = _parser().parse_args(argv)
    all_cases = cases()
    if args.list:
        for c in all_cases:
            print(f"{c.name:32s} {'quick' if c.quick else '     '}  {c.kind}")
        return EXIT_OK
    selected = select(all_cases, args.quick, [n for n in args.cases.split(",") if n])
    runs_dir = args.runs_dir
    os.makedirs(os.path.join(REPO, runs_dir), exist_ok=True)
    meta_path = os.path.join(REPO, runs_dir, "study.json")
    if args.no_run and os.path.exists(meta_path):
        with open(meta_path) as fh:
            meta = json.load(fh)
    else:
        meta = _run_all(selected, runs_dir, args, argv)
        with open(meta_path, "w") as fh:
            json.dump(meta, fh, indent=2)
    results = {c.name: r for c in selected if (r := load(c, runs_dir)) is not None}
    evaluate(results)
    newton_figure(results, os.path.join(REPO, runs_dir, "newton_per_step.png"))
    write_report(results, selected, meta, os.path.join(REPO, runs_dir, "report.md"))
    failed = [c.name for c in selected if c.name not in results or not passed(results[c.name])]
    print(f"hard cases: {len(selected) - len(failed)} of {len(selected)} pass"
          + (f"; failed: {', '.join(failed)}" if failed else "") + f" -> {os.path.join(runs_dir, 'report.md')}")
    return EXIT_FAILED if failed else EXIT_OK


def _run_all(selected, runs_dir, args, argv):
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    loads = []
    if not args.no_run:
        for c in selected:
            loads.append(run_case(c, runs_dir, timeout=args.timeout)["load_avg_1min_after"])
    return {"command": " ".join([".venv/bin/python", "benchmarks/hard_cases.py", *argv]),
            "date": time.strftime("%Y-%m-%d %H:%M"), "wall_s": time.perf_counter() - t0, "load_before": load0,
            "load_mean": float(np.mean(loads)) if loads else load0}


if __name__ == "__main__":
    sys.exit(main())
