"""Weighted least squares of a scene's parameters against station observations (``python -m pfault.calibrate``).

The objective is phi = sum_i ((s_i(p) - o_i) / sigma_i)^2 over every measured component, s_i the run's station
displacement interpolated linearly in time to the observation's time (pfault.post.rundir.StationSeries.at).
It is minimised by scipy.optimize.least_squares with its dogleg method in a rectangular trust region
(method "dogbox", which keeps the parameters within their bounds: on the twin experiment it took 4
iterations where the trust-region reflective method took 10, whose scaling by the distance to the bounds
shortened every step) in the fitted variables x: log10(p) for a log-transformed parameter, p / |p_start| otherwise.

Every evaluation is a pfault run (pfault.tools.runs). The Jacobian is a forward difference, step
DERIVATIVE_STEP in x (a factor 10^0.01 = 1.023 for a log parameter, 1 % of the start otherwise), backward at an
upper bound; its columns are independent runs, made side by side (``--workers``). A trial point whose run
fails counts as an infinite objective (the trust region shrinks); a Jacobian column whose runs fail both ways
stops the fit (ForwardRunFailed).

Uncertainty at the optimum (linearised, as PEST reports it): C_x = s^2 (J^T J)^-1 with J the Jacobian of
the weighted residuals in x and s^2 = phi / (m - n) the residual variance per degree of freedom (m measured
components, n parameters); standard errors sqrt(diag C_x), correlations C_ij / (se_i se_j). For a log
parameter the standard error of log10(p) is the natural one (a factor 10^se either way); its first-order
value p ln(10) se is reported too.

(J^T J)^-1 is taken through the singular values of J: a direction of x along which the residuals do not change
(a singular value at round-off, numerical rank as numpy.linalg.matrix_rank counts it) has an infinite variance, and
so has every parameter that moves along it, where a pseudo-inverse would report a variance of zero. A parameter
is identifiable when its standard error in x is within the span of its bounds in x; one that the observations do
not pin down within its bounds (the compression index Cc of a soil whose heads never went below its
preconsolidation head: no observation depends on it) is reported as not identifiable, not as a fitted number.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..post.rundir import read_station_series
from .calibration_input import Observations, Parameter
from .runs import Run, RunResult, run_many

DERIVATIVE_STEP = 0.01      # forward-difference step in the fitted variables
NULL_LOADING = 1e-8         # a parameter's share of a null direction of J above which its variance is infinite
FTOL = 1e-4                 # relative reduction of phi below which the fit stops (PEST's PHIREDSTP is 0.01)
XTOL = 1e-4                 # relative change of x below which the fit stops


class ForwardRunFailed(Exception):
    """A run the fit cannot go on without failed (the start, or a Jacobian column both ways)."""


@dataclass
class Evaluation:
    number: int
    purpose: str             # start, trial, jacobian, fitted
    values: np.ndarray       # parameter values (SI)
    result: RunResult
    phi: float               # objective (inf when the run failed)
    residual: np.ndarray | None = None      # weighted residuals, None when the run failed


@dataclass
class Problem:
    """The scene, its parameters and observations, and the runs made so far."""
    scene: str
    parameters: list[Parameter]
    observations: Observations
    run_dir: str                         # where the runs write (one directory each)
    workers: int = 1
    ranks: int = 1
    timeout: float | None = None
    log: object = print                  # one line per run
    runner: Callable[[Iterable[Run], int], list[RunResult]] = run_many   # makes the runs (workers side by side)
    insar: Any = None                    # an InSAR time series as observations (pfault.tools.insar_fit.InsarTerm)
    evaluations: list[Evaluation] = field(default_factory=list)
    _cache: dict = field(default_factory=dict)

    # -- the fitted variables
    def scale(self) -> np.ndarray:
        return np.array([1.0 if p.log else abs(p.start) or 1.0 for p in self.parameters])

    def to_x(self, values: Sequence[float] | np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        logs = np.array([p.log for p in self.parameters])
        return np.where(logs, np.log10(np.where(logs, values, 1.0)), values / self.scale())

    def to_values(self, x: Sequence[float] | np.ndarray) -> np.ndarray:
        logs = np.array([p.log for p in self.parameters])
        return np.where(logs, 10.0 ** np.asarray(x), np.asarray(x) * self.scale())

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.to_x([p.lower for p in self.parameters]), self.to_x([p.upper for p in self.parameters]))

    # -- runs
    def overrides(self, values: Sequence[float] | np.ndarray) -> dict[str, str]:
        return {p.option: p.option_value(v) for p, v in zip(self.parameters, values)}

    def evaluate(self, xs: list[np.ndarray], purpose: str) -> list[Evaluation]:
        """Runs the points not run yet, side by side; the evaluation of each point."""
        new = [x for x in dict.fromkeys(x.tobytes() for x in xs) if x not in self._cache]
        numbers = range(len(self.evaluations) + 1, len(self.evaluations) + 1 + len(new))
        extra = self.insar.overrides() if self.insar is not None else {}
        runs = [Run(self.scene, os.path.join(self.run_dir, f"{n:04d}"),
                    {**self.overrides(self.to_values(np.frombuffer(key))), **extra}, self.ranks, False, self.timeout)
                for n, key in zip(numbers, new)]
        for n, key, result in zip(numbers, new, self.runner(runs, self.workers)):
            ev = self._evaluation(n, purpose, self.to_values(np.frombuffer(key)), result)
            self._cache[key] = ev
            self.evaluations.append(ev)
            self.log(self._line(ev))
        return [self._cache[x.tobytes()] for x in xs]

    def _evaluation(self, number, purpose, values, result):
        if not result.ok:
            return Evaluation(number, purpose, values, result, np.inf)
        r = self.weighted_residual(result.run.output_dir)
        return Evaluation(number, purpose, values, result, float(r @ r), r)

    def simulated(self, output_dir: str) -> np.ndarray:
        """The run's value at every observation (m)."""
        obs = self.observations
        series = read_station_series(output_dir)
        sim = np.empty(len(obs.value))
        for name in obs.stations:
            rows = np.flatnonzero(obs.station == name)
            sim[rows] = series[name].at(obs.time[rows])[np.arange(len(rows)), obs.component[rows]]
        return sim

    def weighted_residual(self, output_dir: str) -> np.ndarray:
        """The stations' weighted residuals, then the InSAR product's (pfault.tools.insar_fit)."""
        parts = [(self.simulated(output_dir) - self.observations.value) / self.observations.sigma
                 if len(self.observations.value) else np.zeros(0)]
        if self.insar is not None:
            parts.append(self.insar.residual(output_dir))
        return np.concatenate(parts)

    def size(self) -> int:
        """Measured values: the stations' components and the InSAR values used."""
        return len(self.observations.value) + (self.insar.count() if self.insar is not None else 0)

    def _line(self, ev):
        values = " ".join(f"{p.name}={v:.6g}" for p, v in zip(self.parameters, ev.values))
        status = f"phi {ev.phi:.6g}" if ev.result.ok else f"FAILED ({ev.result.error})"
        return f"run {ev.number:4d} {ev.purpose:<8} {values}  {status}  wall {ev.result.wall:.1f} s"

    # -- what least_squares calls
    def residual(self, x: np.ndarray) -> np.ndarray:
        purpose = "start" if not self.evaluations else "trial"
        ev = self.evaluate([np.array(x, dtype=np.float64)], purpose)[0]
        if ev.residual is None:
            if purpose == "start":
                raise ForwardRunFailed(f"the run at the start values failed: {ev.result.error} "
                                       f"(its log: {ev.result.log})")
            return np.full(self.size(), np.inf)
        return ev.residual

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        x = np.array(x, dtype=np.float64)
        base = self.evaluate([x], "jacobian")[0].residual
        upper = self.bounds()[1]
        steps = np.where(x + DERIVATIVE_STEP <= upper, DERIVATIVE_STEP, -DERIVATIVE_STEP)
        points = [x + s * e for s, e in zip(steps, np.eye(len(x)))]
        evs = self.evaluate(points, "jacobian")
        failed = [j for j, ev in enumerate(evs) if ev.residual is None]
        if failed:                         # the other way
            steps[failed] *= -1
            retry = self.evaluate([x + steps[j] * np.eye(len(x))[j] for j in failed], "jacobian")
            for j, ev in zip(failed, retry):
                if ev.residual is None:
                    raise ForwardRunFailed(f"the runs of the derivative by {self.parameters[j].name} failed both "
                                           f"ways: {ev.result.error} (its log: {ev.result.log})")
                evs[j] = ev
        return np.stack([(ev.residual - base) / s for ev, s in zip(evs, steps)], axis=1)


@dataclass(frozen=True)
class Fit:
    values: np.ndarray           # fitted parameter values (SI)
    x: np.ndarray                # fitted variables
    phi: float
    phi_start: float
    dof: int
    variance: float              # s^2 = phi / dof
    se_x: np.ndarray             # standard errors of the fitted variables (log10 for log parameters)
    se_value: np.ndarray         # first-order standard errors of the values (SI)
    correlation: np.ndarray
    at_bound: np.ndarray         # bool
    identifiable: np.ndarray     # bool: the standard error in x within the span of the bounds in x
    iterations: int
    message: str
    converged: bool
    evaluation: Evaluation       # the run at the optimum


def statistics(jac: np.ndarray, phi: float, values: np.ndarray, log: np.ndarray, scale: np.ndarray,
               nuisance: int = 0) -> tuple[int, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(dof, s^2, covariance of x, se of x, se of the values, correlation) of a weighted least-squares
    optimum whose weighted-residual Jacobian in x is jac; ``nuisance``: parameters eliminated from the residuals
    besides the fitted ones (an InSAR offset per date), which take their degrees of freedom."""
    m, n = jac.shape
    dof = m - n - nuisance
    variance = phi / dof if dof > 0 else np.nan
    cov = variance * _inverse_normal(jac)
    se_x = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    se_value = np.where(log, values * np.log(10.0) * se_x, scale * se_x)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se_x, se_x)
    return dof, variance, cov, se_x, se_value, corr


def _inverse_normal(jac: np.ndarray) -> np.ndarray:
    """(J^T J)^-1 through the singular values of J; a parameter that moves along a null direction of J (singular
    value at round-off) has an infinite variance and NaN covariances."""
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    null = s <= (s.max(initial=0.0) * max(jac.shape) * np.finfo(np.float64).eps)
    inv = (vt.T * np.where(null, 0.0, 1.0 / np.where(null, 1.0, s) ** 2)) @ vt
    free = np.abs(vt[null]).max(axis=0, initial=0.0) > NULL_LOADING
    inv[free, :] = np.nan
    inv[:, free] = np.nan
    inv[free, free] = np.inf
    return inv


def identifiable(se_x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Which parameters the observations pin down: a finite standard error in the fitted variable no larger than
    the span of its bounds there (a parameter known no better than its bounds say was not fitted)."""
    return np.isfinite(se_x) & (se_x <= upper - lower)


def fit(problem: Problem, max_iterations: int = 20) -> Fit:
    from scipy.optimize import least_squares
    x0 = problem.to_x([p.start for p in problem.parameters])
    lower, upper = problem.bounds()
    res = least_squares(problem.residual, x0, jac=problem.jacobian, bounds=(lower, upper), method="dogbox",
                        ftol=FTOL, xtol=XTOL, gtol=1e-10, max_nfev=max_iterations)
    best = problem.evaluate([np.array(res.x, dtype=np.float64)], "fitted")[0]
    best.purpose = "fitted"
    phi = float(best.phi)
    logs = np.array([p.log for p in problem.parameters])
    values = problem.to_values(res.x)
    nuisance = problem.insar.nuisance if problem.insar is not None else 0
    dof, variance, _, se_x, se_value, corr = statistics(res.jac, phi, values, logs, problem.scale(), nuisance)
    return Fit(values, np.array(res.x), phi, problem.evaluations[0].phi, dof, variance, se_x, se_value, corr,
               res.active_mask != 0, identifiable(se_x, lower, upper), int(res.njev), str(res.message),
               bool(res.status > 0), best)
