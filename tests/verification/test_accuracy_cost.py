"""benchmarks/accuracy_cost.py --quick: exit code, the report's tables and figure, and observed convergence rates
within two-sided bounds (a rate that is too good is a bug too).

The whole --quick study (42 runs, 2.5 minutes on the shared 2-core machine) is too long for the suite, which
runs a reduced version by default: the --quick ladders of the manufactured solution, Theis, the penny crack and
the two blocks with the direct solvers only, no tolerance ladder and penalty at 1 and 100 E/h (about a minute).
PFAULT_STUDY_TEST=quick runs the whole --quick study (every problem but the case studies, the iterative
solvers and the tolerance ladder too) and checks the iterative solvers' rates and the oedometer as well. The
case studies are left out in both (their meshes take minutes); the same code runs them in the study itself."""

import json
import os
import subprocess
import sys

import pytest

from conftest import REPO, mpi_env

pytestmark = pytest.mark.mpi
WHOLE = os.environ.get("PFAULT_STUDY_TEST", "") == "quick"
if WHOLE:
    PROBLEMS = "mms,oedometer,theis,penny,two_blocks"
    OPTIONS = []
    ELASTIC, FAULT = ("mumps", "gamg"), ("mumps", "iterative")
else:
    PROBLEMS = "mms,theis,penny,two_blocks"
    OPTIONS = ["--elastic-solvers", "mumps", "--fault-solvers", "mumps", "--rtols", "", "--penalty", "1,100"]
    ELASTIC, FAULT = ("mumps",), ("mumps",)
TIMEOUT = 900


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy_cost")
    proc = subprocess.run([sys.executable, "benchmarks/accuracy_cost.py", "--quick", "--problems", PROBLEMS,
                           "--out", str(out), *OPTIONS], cwd=REPO, env=mpi_env(), capture_output=True, text=True,
                          timeout=TIMEOUT)
    with open(os.path.join(out, "results.json")) as fh:
        results = json.load(fh)
    with open(os.path.join(out, "rates.json")) as fh:
        rates = json.load(fh)
    with open(os.path.join(out, "report.md")) as fh:
        report = fh.read()
    return proc, out, results, rates, report


def rate(rates, problem, series, key="error"):
    found = [r for r in rates if (r["problem"], r["series"], r["key"]) == (problem, series, key)]
    assert len(found) == 1, (problem, series, key, rates)
    return found[0]


def rows(results, problem, series=None):
    return [r for r in results["rows"] if r["problem"] == problem and (series is None or r["series"] == series)]


def test_exit_code_and_every_run_converged(study):
    proc, _, results, _, _ = study
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert all(r["ok"] for r in results["rows"])
    assert "0 failed" in proc.stdout


def test_report_has_one_table_per_problem_and_the_cheapest_settings(study):
    _, out, results, _, report = study
    assert os.path.getsize(os.path.join(out, "error_vs_time.png")) > 10000
    titles = {"mms": "Manufactured solution", "oedometer": "Oedometer", "theis": "Theis drawdown",
              "penny": "Penny-shaped crack", "two_blocks": "Two blocks"}
    for problem in PROBLEMS.split(","):
        assert f"## {titles[problem]}" in report
    assert "## Cheapest setting per error level" in report and "## Observed rates" in report
    assert "| setting | n | h | unknowns | error |" in report
    assert "load average during the runs" in report
    for problem in PROBLEMS.split(","):
        got = rows(results, problem)
        # every table row has unknowns, an error, a wall time; pfault runs have Newton and Krylov counts
        solvers = ELASTIC if problem in ("mms", "oedometer") else FAULT
        assert len(got) >= 3 * len(solvers)
        assert all(r["unknowns"] > 0 and r["error"] is not None and r["wall_s"] > 0 for r in got)
        if problem in ("oedometer", "penny", "two_blocks"):
            assert all(r["newton"] >= 1 and r["krylov"] >= 1 for r in got)
    # the cheapest-setting table has a row per problem, and 10 % is reached everywhere
    table = report.split("## Cheapest setting per error level")[1].split("## Observed rates")[0]
    for problem in PROBLEMS.split(","):
        line = [s for s in table.splitlines() if s.startswith(f"| {problem} |")]
        assert len(line) == 1
        assert line[0].split("|")[3].strip() != "not reached", line


def test_manufactured_solution_rates(study):
    _, _, _, rates, _ = study
    for solver in ELASTIC:
        assert 1.7 <= rate(rates, "mms", solver)["fit"] <= 2.3
        assert 0.8 <= rate(rates, "mms", solver, "H1 error")["fit"] <= 1.2


def test_theis_and_penny_rates(study):
    _, _, _, rates, _ = study
    for solver in ("cg+hypre", "mumps"):
        assert 1.3 <= rate(rates, "theis", solver)["fit"] <= 2.2          # measured 1.52 (n 12, 24, 48)
    for solver in FAULT:
        assert 0.7 <= rate(rates, "penny", solver)["fit"] <= 1.6          # measured 1.13 (RMS); max error 1.54
        assert 1.0 <= rate(rates, "penny", solver, "max error")["fit"] <= 2.0


def test_exact_answers_and_penalty_rate(study):
    """The oedometer and the Lagrange two-block slip are exact on every mesh (their errors are the solver's);
    penalty faces converge at rate 1 in h at a fixed multiple of E/h, with the error ~ 1/k across multiples."""
    _, _, results, rates, _ = study
    if WHOLE:
        assert all(r["error"] < 1e-9 for r in rows(results, "oedometer", "mumps"))
        assert all(r["error"] < 1e-6 for r in rows(results, "oedometer", "gamg"))
    assert all(r["error"] < 1e-8 for r in rows(results, "two_blocks", "mumps"))
    for m in ("1", "100"):
        assert 0.9 <= rate(rates, "two_blocks", f"penalty {m} E/h")["fit"] <= 1.1
    by_level = {r["level"]: r["error"] for r in rows(results, "two_blocks", "penalty 1 E/h")}
    for r in rows(results, "two_blocks", "penalty 100 E/h"):
        assert r["error"] * 100 == pytest.approx(by_level[r["level"]], rel=0.05)
