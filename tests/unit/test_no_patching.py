"""No study, benchmark, script or test replaces an attribute of pfault's modules or classes: a variation is an option
or a part given to the model (its mesh options, initial stress, pore-pressure load, fault laws), never a function or
constant swapped in a run. Plain ``ast`` over the files, no import.

What counts as replacing: an assignment, augmented assignment or ``del`` whose target is an attribute of a name bound
by an import from pfault (``from pfault.mesh import geometry; geometry._QRO_DZ *= 0.25``, ``from pfault.solver.flow
import GroundwaterFlow; GroundwaterFlow.cell_dp = ...``, ``import pfault.x as y; y.f = ...``), and ``setattr`` /
``delattr`` (``monkeypatch.setattr`` included) on such a name or on a dotted ``"pfault.…"`` string; an item stored
into a pfault module's table (``geometry.QUERETARO_DEFAULTS["fault_x"] = ...``). Attributes of objects a test made
(``sim.solver``) and of other libraries are not pfault's modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
FOLDERS = ("tests", "studies", "benchmarks", "scripts")


def _pfault_names(tree: ast.AST) -> set[str]:
    """Names a file binds to pfault's modules or to what it imports from them (in any scope)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update((a.asname or a.name).split(".")[0] for a in node.names
                         if a.name == "pfault" or a.name.startswith("pfault."))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and (
                node.module == "pfault" or node.module.startswith("pfault.")):
            names.update(a.asname or a.name for a in node.names)
    return names


def _root(node: ast.AST) -> str | None:
    while isinstance(node, (ast.Attribute, ast.Subscript, ast.Call)):
        node = node.func if isinstance(node, ast.Call) else node.value
    return node.id if isinstance(node, ast.Name) else None


def patches(source: str) -> list[tuple[int, str]]:
    """(line, text) of every replacement of a pfault attribute in ``source``."""
    tree = ast.parse(source)
    names = _pfault_names(tree)
    found = []
    for node in ast.walk(tree):
        targets = {ast.Assign: lambda n: n.targets, ast.AugAssign: lambda n: [n.target],
                   ast.AnnAssign: lambda n: [n.target], ast.Delete: lambda n: n.targets}.get(type(node))
        for target in targets(node) if targets else ():
            for t in ast.walk(target):
                stored = isinstance(t, (ast.Attribute, ast.Subscript)) and isinstance(t.ctx, (ast.Store, ast.Del))
                if stored and _root(t) in names:
                    found.append((node.lineno, ast.unparse(t)))
        if isinstance(node, ast.Call) and node.args:
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            first = node.args[0]
            dotted = isinstance(first, ast.Constant) and str(first.value).startswith("pfault.")
            if name in ("setattr", "delattr") and (dotted or _root(first) in names):
                found.append((node.lineno, ast.unparse(node)))
    return sorted(set(found))


def test_no_study_benchmark_script_or_test_replaces_a_pfault_attribute():
    found = {f"{path.relative_to(REPO)}:{line}": text
             for folder in FOLDERS for path in sorted((REPO / folder).rglob("*.py"))
             for line, text in patches(path.read_text())}
    assert not found, "replaces pfault's attributes (give the variation as an option or a part): " + "; ".join(
        f"{where} {text}" for where, text in found.items())


def test_the_scan_finds_each_kind_of_replacement():
    source = """
import pfault.mesh.geometry as g
from pfault.mesh import geometry
from pfault.solver import flow
from pfault.solver.equations import Equations
from pfault.tools import calibration as cal
import h5py

def child():
    from pfault.faults import contact
    contact.tensile_strength = lambda c, t: 0 * c
    geometry._QRO_DZ *= 0.25
    g.QUERETARO_SIZE = (1, 1, 1)
    flow.GroundwaterFlow.cell_dp = None
    Equations.geostatic_stress: object = None
    del Equations.effective_stress

def test(monkeypatch, sim):
    monkeypatch.setattr(cal, "run_many", None)
    monkeypatch.setattr("pfault.tools.runs.run_many", None)
    setattr(Equations, "residual", None)
    sim.solver.reuse = None
    h5py.Dataset.__setitem__ = None
    x = geometry.QUERETARO_DEFAULTS["fault_x"]
    geometry.QUERETARO_DEFAULTS["fault_x"] = x
    y = {}
    y["a"] = x
"""
    found = [line for line, _ in patches(source)]
    assert found == [11, 12, 13, 14, 15, 16, 19, 20, 21, 25], patches(source)
