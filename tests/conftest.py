"""Shared helpers: the scenes the tests run most, runs of pfault and of tests/scripts/ (every run under a
timeout), and the comparison of two run directories.

pfault's command line runs in this process on one rank and in a set of MPI workers started once on two
(tests/inprocess.py), where MPI start-up is not what a test is about; anything else is a process started by
pfault.tools.runs (the runner of the studies and the benchmarks too). A process that runs tests starts PETSc once,
with no options, before a test module imports it (pytest_configure); the process that only shares the tests out
between pytest-xdist's workers does not start it (its MPI would be inherited by the workers it starts, and the
mpirun of a worker's run would fail). The repository root goes first on the import path so that the tests import
the studies (studies/) beside the package."""

import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import petsc4py
import pytest
from xdist.scheduler import LoadFileScheduling

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from inprocess import RUNS_HERE, Workers, can_run_here, run_here  # noqa: E402
from pfault.post.rundir import read_fields, read_summary  # noqa: E402
from pfault.tools.runs import command, environment, run_captured  # noqa: E402,F401  (command, run_captured: tests)

PY = sys.executable

# the scenes the tests run most (paths relative to the repository, where the tests run)
OEDOMETER = "config/oedometer.opts"
TWO_BLOCKS = "config/two_blocks.opts"
FISSURE_BOX = "config/hard/fissure_box.opts"
QUERETARO = "config/queretaro.opts"
WUXI = "config/wuxi.opts"
TIMEOUT = 600

# a 2x2x2-cell box drained by one well, no fault (written by the flow_box fixture; the tests give its time grid)
FLOW_BOX = """# a 2x2x2-cell box drained by one well, no fault
-pfault_box_size 10,10,20
-pfault_box_cells 2,2,2
-pfault_material_soil_young_modulus 10*MPa
-pfault_material_soil_poisson_ratio 0.25
-pfault_material_soil_hydraulic_conductivity 1*m/day
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_bc_bottom_type fixed
-pfault_flow true
-pfault_flow_wells 5,5
-pfault_flow_well_screen -1,-15
-pfault_flow_well_rate 0:0,1*day:3*L/s
-pfault_flow_fixed_head_surfaces xmin
-pfault_solver mumps
"""


def write_flow_box(directory):
    """The flow box's options file in ``directory``; returns its path."""
    path = os.path.join(str(directory), "flow_box.opts")
    with open(path, "w") as fh:
        fh.write(FLOW_BOX)
    return path


@pytest.fixture
def flow_box(tmp_path):
    """Path of the flow box's options file (FLOW_BOX), in the test's tmp_path."""
    return write_flow_box(tmp_path)


def mpi_env():
    """The tests' runs' environment: pfault.tools.runs.environment, more ranks than cores allowed, and ranks that
    yield their core while they wait for a message: the suite's workers run side by side on the cores, and a rank
    spinning in a receive would take the core its partner needs."""
    env = environment(oversubscribe=True)
    env["OMPI_MCA_mpi_yield_when_idle"] = "1"
    return env


WORKERS = Workers(mpi_env(), REPO)      # the MPI workers of the session's 2-rank runs (tests/inprocess.py)


def run(args, ranks=1, timeout=TIMEOUT, check=True, cwd=REPO, here=True):
    """``python ARGS`` on ``ranks`` ranks from ``cwd`` (the repository's root); the CompletedProcess, checked to
    exit 0 unless ``check`` is False. pfault's command line runs in this process on one rank and in the MPI
    workers on two (tests/inprocess.py); anything else, and every run with ``here=False``, is a process (under
    mpirun on more ranks). A run past ``timeout`` s fails the test."""
    try:
        if ranks == 1 and here and can_run_here(args):
            proc = run_here(args, str(cwd), timeout)
        elif ranks == 2 and here and can_run_here(args):
            proc = WORKERS.run(args, ranks, str(cwd), timeout)
        else:
            proc = run_captured(args, ranks, cwd=cwd, env=mpi_env(), timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{' '.join(map(str, args))} on {ranks} rank(s) did not end within {timeout} s\n"
                    f"stdout:\n{(exc.stdout or '')[-4000:]}\nstderr:\n{(exc.stderr or '')[-4000:]}")
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(args)} on {ranks} rank(s) exited {proc.returncode}\n"
                             f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}")
    return proc


def run_scene(scene, outdir, ranks=1, extra=(), check=True, here=True):
    """A run of ``scene`` into ``outdir`` (no PNG figures unless ``extra`` asks for them: matplotlib adds ~3 s to
    every run); (CompletedProcess, its summary.json or None)."""
    figures = [] if "-pfault_figures" in extra else ["-pfault_figures", "false"]
    proc = run(["-m", "pfault", scene, "-pfault_output_dir", str(outdir), *figures, *extra], ranks=ranks,
               check=check, here=here)
    return proc, read_summary(outdir)


@pytest.fixture(scope="session")
def shared_run(tmp_path_factory):
    """A run made once for every test, in any module and on any of the suite's workers, that asks for the same
    scene, ranks and options: ``shared_run(scene, ranks=1, extra=())`` -> (summary, output directory). Its
    directory is read, never written to (a test that continues or changes a run copies it first). The workers
    share the session's directory; a lock file per run makes one of them make it while the others wait."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent

    def get(scene, ranks=1, extra=()):
        extra = tuple(map(str, extra))
        key = hashlib.sha256(repr((scene, ranks, extra)).encode()).hexdigest()[:12]
        out = root / f"shared-{os.path.splitext(os.path.basename(scene))[0]}-r{ranks}-{key}"
        with open(f"{out}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                if not os.path.exists(f"{out}.done"):
                    shutil.rmtree(out, ignore_errors=True)
                    run_scene(scene, out, ranks=ranks, extra=extra)
                    open(f"{out}.done", "w").close()
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
        return read_summary(out), out
    return get


FAULTED_AQUIFER = "config/faulted_aquifer.opts"
SAND_MODULUS = "-pfault_material_sand_young_modulus 60*MPa\n"
SAND_INDICES = ("-pfault_material_sand_compression_index 0.05\n-pfault_material_sand_recompression_index 0.01\n"
                "-pfault_material_sand_void_ratio 0.7\n")


def soil_aquifer_slice(directory, size_factor, name):
    """The faulted aquifer's 40 m slice at ``size_factor`` (benchmarks/faulted_aquifer_mesh.py) and the scene
    ``name`` in ``directory``: config/faulted_aquifer.opts with its sand normally consolidated (Cc 0.05, Cr 0.01,
    e0 0.7) in place of its drained modulus; (scene path, mesh path)."""
    msh = str(directory / "slice.msh")
    run([os.path.join("benchmarks", "faulted_aquifer_mesh.py"), msh, "--strike-length", "40",
         "--size-factor", str(size_factor)], timeout=300)
    with open(os.path.join(REPO, FAULTED_AQUIFER)) as fh:
        text = fh.read()
    assert SAND_MODULUS in text
    scene = directory / name
    scene.write_text(text.replace(SAND_MODULUS, SAND_INDICES))
    return str(scene), msh


def run_script(script, ranks=1, args=()):
    """Run tests/scripts/<script> and parse the JSON it prints on its last line."""
    proc = run([os.path.join("tests", "scripts", script), *args], ranks=ranks)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def read_last_step(outdir):
    """(points, time, point data, cell data as meshio gives it: a list of one array per name) of fields.xdmf's last
    output time (pfault.post.rundir.read_fields)."""
    snap = read_fields(str(outdir))
    return snap.points, snap.time, snap.point_data, {k: [v] for k, v in snap.cell_data.items()}


@pytest.fixture
def repo():
    return REPO


# the maxima of summary.json that two runs of the same scene must share
MAXIMA = ("max_subsidence_m", "max_horizontal_displacement_m", "max_fault_opening_m", "max_fault_slip_m",
          "max_horizontal_strain", "max_angular_distortion")


# A dataset whose exact value is zero (a glued face's jump, the horizontal strain of a uniformly sheared surface, the
# shear traction of a face pressed straight) holds round-off of the quantities it is computed from; two runs that
# took different but equally converged paths differ there by 100 % of the dataset. Such datasets are measured
# against the scale of what they are computed from: a fault's jumps against the step's largest displacement, its
# tractions against the step's largest traction, the surface's strains against its largest strain and its largest
# displacement over its extent.
JUMPS = ("opening", "slip", "slip_magnitude")
TRACTIONS = ("traction_normal", "traction_normal_effective", "traction_shear")
STRAINS = ("horizontal_strain", "angular_distortion")
STRAINS_MAXIMA = ("max_horizontal_strain", "max_angular_distortion")
# a soil's head margin is exactly zero on the virgin line up to the round-off of the stresses it is computed from:
# measured, with the critical heads, against the largest of them (fields.h5 per cell, surface.h5 per layer)
HEADS = ("head_margin", "preconsolidation_head", "critical_head")


def _round_off_scales(name, group, moved, extent):
    def largest(keys):
        return max((float(np.max(np.abs(group[k][0]), initial=0.0)) for k in keys if k in group), default=0.0)
    scales = {}
    if name == "fault":
        scales.update({k: max(moved, largest(JUMPS)) for k in JUMPS})
        scales.update({k: largest(TRACTIONS) for k in TRACTIONS})
    elif name == "surface":
        strain = max(largest(STRAINS), largest(("displacement",)) / extent)
        scales.update({k: strain for k in STRAINS})
    heads = [k for k in group if k.startswith(HEADS)]
    scales.update({k: largest(heads) for k in heads})
    return scales


def compare_runs(ref_dir, other_dir, rtol):
    """Largest relative difference over every output dataset of the two runs (same steps asserted) and over
    the summary maxima; asserts each is within rtol."""
    import h5py
    worst = 0.0
    strain_scale = 0.0      # the surface strains' scale over the steps (_round_off_scales)
    moved = {}      # the largest displacement of each step
    fields = os.path.join(ref_dir, "fields.h5")
    if os.path.exists(fields):
        with h5py.File(fields, "r") as a:
            moved = {step: float(np.max(np.abs(g["displacement"][()]), initial=0.0))
                     for step, g in a["steps"].items() if "displacement" in g}
    for name in ("fields", "fault", "surface"):
        path = os.path.join(ref_dir, name + ".h5")
        if not os.path.exists(path):
            assert not os.path.exists(os.path.join(other_dir, name + ".h5"))
            continue
        with h5py.File(path, "r") as a, h5py.File(os.path.join(other_dir, name + ".h5"), "r") as b:
            assert sorted(a["steps"]) == sorted(b["steps"]), name
            extent = 1.0
            if "mesh" in a and "points" in a["mesh"]:
                pts = a["mesh"]["points"][()]
                extent = max(float(np.max(np.ptp(pts, axis=0), initial=0.0)), 1e-300)
            for step in a["steps"]:
                ga, gb = a["steps"][step], b["steps"][step]
                assert ga.attrs["time"] == pytest.approx(gb.attrs["time"], rel=1e-14)
                assert sorted(ga) == sorted(gb)
                group = {}
                for key in ga:
                    x, y = ga[key][()], gb[key][()]
                    if np.issubdtype(x.dtype, np.floating):
                        # NaN where a value does not exist (an intact face's break time): in the same places
                        assert np.array_equal(np.isnan(x), np.isnan(y)), f"{name}.h5 step {step} {key}: NaN"
                        x, y = np.nan_to_num(x), np.nan_to_num(y)
                    group[key] = (x, y)
                scales = _round_off_scales(name, group, moved.get(step, 0.0), extent)
                strain_scale = max(strain_scale, scales.get(STRAINS[0], 0.0))
                for key, (x, y) in group.items():
                    scale = max(float(np.max(np.abs(x), initial=0.0)), scales.get(key, 0.0), 1e-300)
                    diff = float(np.max(np.abs(x - y), initial=0.0)) / scale
                    assert diff <= rtol, f"{name}.h5 step {step} {key}: relative difference {diff:.3g}"
                    worst = max(worst, diff)
    sa, sb = read_summary(ref_dir), read_summary(other_dir)
    jump = max(sa.get("max_fault_opening_m", 0.0), sa.get("max_fault_slip_m", 0.0))
    extent = 1.0
    if os.path.exists(fields):
        with h5py.File(fields, "r") as a:
            extent = max(float(np.max(np.ptp(a["mesh"]["points"][()], axis=0), initial=0.0)), 1e-300)
    moved_most = max(sa.get("max_subsidence_m", 0.0), sa.get("max_horizontal_displacement_m", 0.0))
    for key in MAXIMA:
        floor = rtol * jump if key == "max_fault_opening_m" else 0.0     # (round-off where no face opens)
        if key in STRAINS_MAXIMA:       # (round-off where the surface stays flat: against what they are computed from)
            floor = rtol * max([sa[k] for k in STRAINS_MAXIMA] + [strain_scale, moved_most / extent])
        assert sb[key] == pytest.approx(sa[key], rel=rtol, abs=max(floor, 1e-300)), key
    assert [r["step"] for r in sb["steps"]] == [r["step"] for r in sa["steps"]]
    assert sb["completed_steps"] == sa["completed_steps"]
    return worst


class HeaviestFileFirst(LoadFileScheduling):
    """pytest-xdist's file-by-file scheduling (--dist loadfile), the files taken heaviest first by the seconds they
    took (tests/durations.json, written by scripts/test_durations.py; a file not in it counts as the median file)
    instead of by their number of tests: heavy files of one or two tests (the calibrations' twins) ran last, one
    worker on its own for a minute at the end of the suite."""

    def __init__(self, config, log=None):
        super().__init__(config, log)
        with open(os.path.join(REPO, "tests", "durations.json")) as fh:
            self.seconds = json.load(fh)
        self.median = float(np.median(list(self.seconds.values()))) if self.seconds else 0.0

    def _assign_work_unit(self, node):
        heaviest = max(self.workqueue, key=lambda scope: self.seconds.get(scope, self.median))
        self.workqueue.move_to_end(heaviest, last=False)
        super()._assign_work_unit(node)


def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") == "loadfile":
        return HeaviestFileFirst(config, log)
    return None


def pytest_configure(config):
    """PETSc started with no options (pytest's arguments are not PETSc's) in a process that runs tests."""
    shares_out = getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput")
    if not shares_out:
        petsc4py.init([sys.argv[0]])


def pytest_sessionfinish(session):
    WORKERS.close()


def pytest_terminal_summary(terminalreporter, config):
    if getattr(config.option, "numprocesses", None):
        return                  # (the counts are the workers')
    terminalreporter.write_line(f"pfault tests: {RUNS_HERE[0]} runs of pfault in the test process, {RUNS_HERE[1]} in "
                                "MPI workers")
