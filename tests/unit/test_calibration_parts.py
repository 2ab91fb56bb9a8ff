"""The calibration's pieces without pfault runs (pfault.tools): the linearised statistics against NumPy's
weighted polynomial fit, the fitted variables, the residuals from a run's station file, and the readers."""

import os

import numpy as np
import pytest

from pfault.tools.calibration import Problem, identifiable, statistics
from pfault.tools.calibration_input import (CalibrationInputError, Observations, read_observations,
                                            read_parameters)
from pfault.post.rundir import StationSeries, read_station_series
from pfault.tools.runs import error_line, option_args


def test_statistics_of_a_straight_line_equal_numpy_polyfit():
    """Weighted y = a + b t: s^2 (J^T J)^-1 is polyfit's covariance (scaled by chi^2 / (m - n))."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 10.0, 25)
    sigma = 0.1 + 0.05 * t
    y = 2.0 - 0.7 * t + sigma * rng.standard_normal(t.size)
    coef, cov = np.polyfit(t, y, 1, w=1 / sigma, cov=True)          # [b, a]
    jac = np.stack([np.ones_like(t), t], axis=1) / sigma[:, None]    # d(weighted residual)/d(a, b)
    r = (coef[1] + coef[0] * t - y) / sigma
    dof, variance, cov_x, se_x, se_value, corr = statistics(jac, float(r @ r), coef[::-1], np.array([False] * 2),
                                                            np.ones(2))
    assert dof == 23 and variance == pytest.approx(float(r @ r) / 23, rel=1e-14)
    assert np.allclose(cov_x, cov[::-1, ::-1], rtol=1e-10, atol=0)
    assert np.allclose(se_x, np.sqrt(np.diag(cov))[::-1], rtol=1e-10)
    assert np.allclose(se_value, se_x)
    assert corr[0, 1] == pytest.approx(cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]), rel=1e-10)
    assert np.allclose(np.diag(corr), 1.0)


def test_standard_error_of_a_log_parameter_is_first_order_in_the_value():
    jac = np.array([[1.0], [2.0], [-1.0]])
    _, variance, _, se_x, se_value, _ = statistics(jac, 4.0, np.array([1e7]), np.array([True]), np.ones(1))
    assert se_x[0] == pytest.approx(np.sqrt(2.0 / 6.0), rel=1e-14)
    assert se_value[0] == pytest.approx(1e7 * np.log(10) * se_x[0], rel=1e-14)


def test_a_parameter_no_residual_depends_on_has_an_infinite_standard_error_not_zero():
    """A zero Jacobian column (a soil's Cc whose heads never reach its preconsolidation head): a pseudo-inverse
    would give it a variance of 0; its variance is infinite, it is not identifiable, and the other parameters'
    statistics are those of the fit without it."""
    rng = np.random.default_rng(5)
    jac = np.column_stack([rng.standard_normal(30), np.zeros(30), rng.standard_normal(30)])
    values, log, scale = np.array([1.0, 0.3, 2.0]), np.array([False, True, False]), np.ones(3)
    dof, variance, cov, se_x, se_value, corr = statistics(jac, 27.0, values, log, scale)
    assert dof == 27 and variance == 1.0
    assert se_x[1] == np.inf and se_value[1] == np.inf and np.isnan(corr[1, 0]) and np.isnan(corr[0, 1])
    alone = statistics(jac[:, [0, 2]], 27.0, values[[0, 2]], log[[0, 2]], scale[:2])
    assert np.allclose(se_x[[0, 2]], alone[3] * np.sqrt(28 / 27), rtol=1e-12)     # one dof fewer there
    assert corr[0, 2] == pytest.approx(alone[5][0, 1], rel=1e-12)
    lower, upper = np.array([-5.0, -2.0, -5.0]), np.array([5.0, 0.0, 5.0])
    assert identifiable(se_x, lower, upper).tolist() == [True, False, True]
    # a column at the forward runs' round-off (1e-9 of the others): finite but beyond its bounds' span of 2
    jac[:, 1] = 1e-9 * rng.standard_normal(30)
    se = statistics(jac, 27.0, values, log, scale)[3]
    assert 1e7 < se[1] < 1e10 and identifiable(se, lower, upper).tolist() == [True, False, True]


def write(path, text):
    path.write_text(text)
    return str(path)


def test_parameters_with_units_log_by_default_for_moduli_and_a_template(tmp_path):
    path = write(tmp_path / "p.csv", "# moduli and a rate\nname,option,start,lower,upper,transform,value\n"
                 "E,-pfault_material_clay_young_modulus,10*MPa,1*MPa,100*MPa,,\n"
                 "nu,pfault_material_clay_poisson_ratio,0.3,0.1,0.45,,\n"
                 'Q,-pfault_flow_well_rate,2*L/s,0.5*L/s,20*L/s,log,"0:{Q},1*year:{Q}"\n')
    e, nu, q = read_parameters(path)
    assert (e.option, e.start, e.lower, e.upper, e.log) == ("pfault_material_clay_young_modulus", 1e7, 1e6, 1e8, True)
    assert not nu.log and nu.option_value(0.25) == "0.25"
    assert q.log and q.start == pytest.approx(2e-3) and q.option_value(3e-3) == "0:0.003,1*year:0.003"


def test_soil_indices_are_log_by_default_the_preconsolidation_head_is_not(tmp_path):
    path = write(tmp_path / "p.csv", "name,option,start,lower,upper\n"
                 "Cc,-pfault_material_clay_compression_index,0.2,0.02,2\n"
                 "Cr,-pfault_material_clay_recompression_index,0.02,0.002,0.2\n"
                 "hp,-pfault_material_clay_preconsolidation_head,-3,-10,0\n"
                 "Sskv,-pfault_material_sand_inelastic_skeletal_specific_storage,1e-4,1e-6,1e-2\n")
    cc, cr, hp, sskv = read_parameters(path)
    assert cc.log and cr.log and sskv.log and not hp.log
    assert (hp.start, hp.lower, hp.upper) == (-3.0, -10.0, 0.0)
    assert Problem("s.opts", [cc, cr, hp], None, str(tmp_path)).bounds()[1].tolist() == [pytest.approx(np.log10(2)),
                                                                                          pytest.approx(-0.69897),
                                                                                          0.0]


def test_fitted_variables_and_their_bounds(tmp_path):
    path = write(tmp_path / "p.csv", "name,option,start,lower,upper,transform\n"
                 "E,-pfault_material_clay_young_modulus,1e7,1e6,1e8,log\n"
                 "nu,-pfault_material_clay_poisson_ratio,-0.2,-0.5,0.45,none\n")
    problem = Problem("s.opts", read_parameters(path), None, str(tmp_path))
    x = problem.to_x([1e7, -0.2])
    assert np.allclose(x, [7.0, -1.0]) and np.allclose(problem.to_values(x), [1e7, -0.2], rtol=1e-15)
    lower, upper = problem.bounds()
    assert np.allclose(lower, [6.0, -2.5]) and np.allclose(upper, [8.0, 2.25])
    assert problem.overrides([2e7, 0.1]) == {"pfault_material_clay_young_modulus": "20000000.0",
                                             "pfault_material_clay_poisson_ratio": "0.1"}


def test_residuals_interpolate_the_station_file_linearly_in_time(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "station_displacement.csv").write_text(
        "name,time_s,ux_m,uy_m,uz_m,side\nA,0.0,0,0,0,\nB,0.0,0,0,0,\n"
        "A,10.0,0.1,0.2,-1.0,\nB,10.0,1,2,3,minus\nA,20.0,0.3,0.2,-3.0,\nB,20.0,1,2,5,minus\n")
    series = read_station_series(str(run))
    assert np.allclose(series["A"].at([5.0, 15.0]), [[0.05, 0.1, -0.5], [0.2, 0.2, -2.0]])
    obs = Observations(np.array(["A", "B", "A"]), np.array([15.0, 12.5, 5.0]), np.array([2, 2, 0]),
                       np.array([-1.0, 3.0, 0.0]), np.array([0.5, 2.0, 0.01]))
    problem = Problem("s.opts", [], obs, str(tmp_path))
    assert np.allclose(problem.simulated(str(run)), [-2.0, 3.5, 0.05])
    assert np.allclose(problem.weighted_residual(str(run)), [-2.0, 0.25, 5.0])


def test_observations_with_missing_components_and_units(tmp_path):
    path = write(tmp_path / "o.csv", "name,time,ux,uy,uz,sigma\nA,30*day,,,-0.01,2*mm\nB,86400,0.001,,-0.02,0.002\n")
    obs = read_observations(path, ["A", "B"], "stations.csv", 1e7)
    assert obs.station.tolist() == ["A", "B", "B"] and obs.component.tolist() == [2, 0, 2]
    assert np.allclose(obs.time, [30 * 86400.0, 86400.0, 86400.0]) and np.allclose(obs.sigma, 0.002)
    with pytest.raises(CalibrationInputError, match=r"line 2: time 2.592e\+06 s is outside the scene's 0 to "
                                                    r"1e\+06 s \(-pfault_time_end\)"):
        read_observations(path, ["A", "B"], "stations.csv", 1e6)


def test_runs_helpers():
    assert option_args({"pfault_a": "1", "-b": 2}) == ["-pfault_a", "1", "-b", "2"]
    assert error_line("x\npfault: error: one\nmore\n  pfault: error: two\n") == "pfault: error: two"
    assert error_line("all good") is None
    s = StationSeries(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]))
    assert np.allclose(s.at([0.25]), [[0.25, 0.5, 0.75]])


def fake_runs(model, fail):
    """run_many's stand-in: 'runs' a two-station model u(t) = model(p, t) written as pfault writes stations;
    values where fail(p) is true exit 1 with a pfault error line."""
    from pfault.tools.runs import RunResult

    def run_many(runs, workers=1, cwd=None, env=None):
        results = []
        for run in runs:
            p = np.array([float(v) for v in run.overrides.values()])
            os.makedirs(run.output_dir)
            if fail(p):
                results.append(RunResult(run, 1, 0.0, "pfault: error: -pfault_x: out of range",
                                         run.output_dir + ".log"))
                continue
            with open(os.path.join(run.output_dir, "station_displacement.csv"), "w") as fh:
                fh.write("name,time_s,ux_m,uy_m,uz_m,side\n")
                for t in np.linspace(0.0, 10.0, 11):
                    a, b = model(p, t)
                    fh.write(f"A,{t!r},0.0,0.0,{a!r},\nB,{t!r},{b!r},0.0,0.0,\n")
            results.append(RunResult(run, 0, 0.0, None, run.output_dir + ".log"))
        return results
    return run_many


def test_the_loop_recovers_an_analytic_model_through_failed_runs(tmp_path):
    """u_z(A) = -k t / E, u_x(B) = k t^2 / (100 E) + c: E (log) and c (linear) from exact data; every run with
    E > 2.52 or within 2.39-2.41 fails: the trial point there (the second) shrinks the trust region, and the
    derivative by E near the optimum (a forward step to 2.5 x 1.023) fails and is taken backward."""
    from pfault.tools import calibration as cal

    def model(p, t):
        return -2.0 * t / p[0], 2.0 * t * t / (100.0 * p[0]) + p[1]

    def fails(p):
        return p[0] > 2.52 or 2.39 < p[0] < 2.41

    params = write(tmp_path / "p.csv", "name,option,start,lower,upper,transform\n"
                   "E,-pfault_material_a_young_modulus,1,0.1,10,log\n"
                   "c,-pfault_material_a_poisson_ratio,0.2,-1,1,none\n")
    true = np.array([2.5, 0.05])
    t = np.array([2.0, 4.0, 6.0, 8.0, 10.0])
    a, b = model(true, t)
    obs = Observations(np.array(["A"] * 5 + ["B"] * 5), np.concatenate([t, t]), np.array([2] * 5 + [0] * 5),
                       np.concatenate([a, b]), np.full(10, 0.01))
    problem = cal.Problem("s.opts", read_parameters(params), obs, str(tmp_path / "runs"), log=lambda line: None,
                          runner=fake_runs(model, fails))
    result = cal.fit(problem)
    assert result.converged and np.allclose(result.values, true, rtol=1e-6)
    assert result.phi < 1e-6 * result.phi_start and result.dof == 8
    failed = [ev for ev in problem.evaluations if not ev.result.ok]
    assert all(fails(ev.values) and ev.phi == np.inf for ev in failed)
    assert {ev.purpose for ev in failed} == {"trial", "jacobian"}
    # every failed Jacobian column was followed by its backward run, which succeeded
    for ev in failed:
        if ev.purpose == "jacobian":
            back = problem.evaluations[ev.number]          # the next run
            assert back.result.ok and back.values[0] < ev.values[0]
    assert sum(ev.purpose == "fitted" for ev in problem.evaluations) == 1


def test_fitted_options_name_the_scene_s_files_by_absolute_paths(tmp_path, monkeypatch):
    """The example site names its heads, stations and clay map beside the scene: a file of options elsewhere that
    includes it (fitted.opts) gets them as absolute paths, a field's settings kept."""
    from pfault.tools.calibration_input import scene_files_absolute
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    site = os.path.join(repo, "config", "site_example")
    monkeypatch.chdir(tmp_path)
    files = scene_files_absolute(os.path.join(site, "site.opts"))
    assert files == {"pfault_stations": os.path.join(site, "stations.csv"),
                     "pfault_heads_file": os.path.join(site, "site.nc"),
                     "pfault_material_clay_young_modulus": "field:" + os.path.join(site, "site_clay_modulus.csv")}
    (tmp_path / "scenes").mkdir()
    scene = tmp_path / "scenes" / "scene.opts"
    scene.write_text("-pfault_stations stations.csv\n"
                     "-pfault_material_sand_young_modulus field:map.csv,outside=nearest\n-pfault_heads_file here.hds\n")
    (tmp_path / "scenes" / "stations.csv").write_text("name,x,y,z\n")
    (tmp_path / "scenes" / "map.csv").write_text("x,y,value\n")
    (tmp_path / "here.hds").write_text("")                      # from the working directory first
    assert scene_files_absolute(str(scene)) == {
        "pfault_stations": str(tmp_path / "scenes" / "stations.csv"),
        "pfault_material_sand_young_modulus": f"field:{tmp_path / 'scenes' / 'map.csv'},outside=nearest",
        "pfault_heads_file": str(tmp_path / "here.hds")}
