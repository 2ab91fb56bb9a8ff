"""The package's shape (issue 30, "Must hold"): no class over 250 lines or 20 instance attributes, no function over
60 lines, in pfault/; type hints on every public function and method; imports at the top of the file (but the
heavy dependencies a run may not need, and PETSc/MPI where a module is imported without them) and no import cycle
among pfault's modules. Lines of tables (dict, list, tuple and set displays of constants, names and calls on them,
three lines or more) do not count. Plain ``ast``, no MPI.

A class's instance attributes are the names its methods assign on their first argument (``self.x = ...``, also
through tuples, ``+=`` and annotations) together with the annotated names of its body (dataclass fields; ClassVar
excepted). A function's lines run from its ``def`` (decorators excluded) to its last line, nested functions
included, so a function is measured as a reader meets it.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "pfault"
REPO = PACKAGE.parent
MAX_CLASS_LINES = 250
MAX_CLASS_ATTRIBUTES = 20
MAX_FUNCTION_LINES = 60
MIN_TABLE_LINES = 3

# Exceptions, each with its reason; an entry that no longer exceeds its limit is an error too (take it out).
ALLOWED: dict[str, str] = {}


# Modules whose public functions may lack type hints, with the reason
UNTYPED: dict[str, str] = {}


def _is_literal(node: ast.AST) -> bool:
    """A table's entry: constants, names, attributes, arithmetic on them, displays and calls of them."""
    if isinstance(node, (ast.Constant, ast.Name, ast.Attribute)):
        return True
    if isinstance(node, ast.UnaryOp):
        return _is_literal(node.operand)
    if isinstance(node, ast.BinOp):
        return _is_literal(node.left) and _is_literal(node.right)
    if isinstance(node, (ast.List, ast.Tuple, ast.Set)):
        return all(_is_literal(e) for e in node.elts)
    if isinstance(node, ast.Dict):
        return all(k is None or _is_literal(k) for k in node.keys) and all(_is_literal(v) for v in node.values)
    if isinstance(node, ast.Call):
        return (isinstance(node.func, (ast.Name, ast.Attribute)) and all(_is_literal(a) for a in node.args)
                and all(_is_literal(k.value) for k in node.keywords))
    if isinstance(node, ast.Starred):
        return _is_literal(node.value)
    return False


def _table_lines(node: ast.AST) -> set[int]:
    """Line numbers inside ``node`` taken by tables (outermost displays of literals over MIN_TABLE_LINES)."""
    lines: set[int] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, (ast.Dict, ast.List, ast.Tuple, ast.Set)) and _is_literal(n):
            if n.end_lineno - n.lineno + 1 >= MIN_TABLE_LINES:
                lines.update(range(n.lineno, n.end_lineno + 1))
                continue
        stack.extend(ast.iter_child_nodes(n))
    return lines


def _length(node: ast.AST) -> int:
    return node.end_lineno - node.lineno + 1 - len(_table_lines(node))


def _targets(target: ast.AST, self_name: str) -> set[str]:
    if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id == self_name:
        return {target.attr}
    if isinstance(target, (ast.Tuple, ast.List)):
        return set().union(*(_targets(e, self_name) for e in target.elts))
    if isinstance(target, ast.Starred):
        return _targets(target.value, self_name)
    return set()


def _is_classvar(annotation: ast.AST) -> bool:
    node = annotation.value if isinstance(annotation, ast.Subscript) else annotation
    return (isinstance(node, ast.Name) and node.id == "ClassVar") or \
        (isinstance(node, ast.Attribute) and node.attr == "ClassVar")


def instance_attributes(cls: ast.ClassDef) -> set[str]:
    names = {s.target.id for s in cls.body
             if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name) and not _is_classvar(s.annotation)}
    for method in cls.body:
        if not isinstance(method, (ast.FunctionDef, ast.AsyncFunctionDef)) or not method.args.args:
            continue
        if any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in method.decorator_list):
            continue
        self_name = method.args.args[0].arg
        for n in ast.walk(method):
            if isinstance(n, ast.Assign):
                for t in n.targets:
                    names |= _targets(t, self_name)
            elif isinstance(n, (ast.AugAssign, ast.AnnAssign)):
                names |= _targets(n.target, self_name)
    return names


def offenders(root: Path = PACKAGE) -> dict[str, str]:
    """{"path::qualified name": what exceeds its limit} for every module under ``root``."""
    found: dict[str, str] = {}

    def visit(node: ast.AST, path: str, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                name = prefix + child.name
                n_lines, attrs = _length(child), instance_attributes(child)
                what = []
                if n_lines > MAX_CLASS_LINES:
                    what.append(f"{n_lines} lines")
                if len(attrs) > MAX_CLASS_ATTRIBUTES:
                    what.append(f"{len(attrs)} instance attributes")
                if what:
                    found[f"{path}::{name}"] = "class: " + ", ".join(what)
                visit(child, path, name + ".")
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                n_lines = _length(child)
                if n_lines > MAX_FUNCTION_LINES:
                    found[f"{path}::{name}"] = f"function: {n_lines} lines"
                visit(child, path, name + ".")
            else:
                visit(child, path, prefix)

    for file in sorted(root.rglob("*.py")):
        path = file.relative_to(root.parent).as_posix()
        visit(ast.parse(file.read_text(), filename=str(file)), path, "")
    return found


def _missing_hints(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> list[str]:
    args = fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs
    if method and args and not any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in fn.decorator_list):
        args = args[1:]         # self, cls
    missing = [a.arg for a in args if a.annotation is None]
    missing += ["*" + a.arg for a in (fn.args.vararg, fn.args.kwarg) if a is not None and a.annotation is None]
    return missing + (["return"] if fn.returns is None else [])


def untyped(root: Path = PACKAGE) -> dict[str, list[str]]:
    """{"path::qualified name": the parameters (and "return") without a hint} for every public function and
    every public method (``__init__`` included) of a public class under ``root``."""
    found: dict[str, list[str]] = {}

    def visit(node: ast.AST, path: str, prefix: str, in_class: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef) and not child.name.startswith("_"):
                visit(child, path, prefix + child.name + ".", True)
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                    (not child.name.startswith("_") or child.name == "__init__"):
                missing = _missing_hints(child, in_class)
                if missing:
                    found[f"{path}::{prefix}{child.name}"] = missing

    for file in sorted(root.rglob("*.py")):
        path = file.relative_to(root.parent).as_posix()
        visit(ast.parse(file.read_text(), filename=str(file)), path, "", False)
    return found


def test_no_class_or_function_over_its_limit():
    over = {k: v for k, v in offenders().items() if k not in ALLOWED}
    assert not over, "over the size limits (split by meaning): " + "; ".join(f"{k} ({v})" for k, v in over.items())


def test_every_exception_is_still_needed():
    found = offenders()
    stale = [k for k in ALLOWED if k not in found]
    assert not stale, f"within the limits now, take them out of ALLOWED: {stale}"


def test_public_functions_have_type_hints():
    missing = {k: v for k, v in untyped().items() if not k.startswith(tuple(UNTYPED))}
    assert not missing, "without type hints: " + "; ".join(f"{k} ({', '.join(v)})" for k, v in missing.items())


def test_checker_measures_lines_attributes_and_tables(tmp_path):
    """The checker on a made-up package: functions of 61 and 60 lines, a table that does not count, a class with
    22 attributes (assigned through self, a tuple, an annotation; a static method's first argument is not self)
    and a dataclass-like class with 21 fields (a ClassVar is not one)."""
    body = "\n".join(f"    x{i} = {i}" for i in range(59))
    table = "\n".join(f"    {i!r}: ({i}, 'a', f(b=-1 * u)),"for i in range(80))
    attrs = "\n".join(f"        self.a{i} = {i}" for i in range(19))
    fields = "\n".join(f"    f{i}: int" for i in range(21))
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text(
        f"def long():\n{body}\n    return 0\n\n"
        f"def at_limit():\n{body}\n\n"
        f"def with_table():\n    t = {{\n{table}\n    }}\n    return t\n\n"
        f"class Many:\n    def __init__(self):\n{attrs}\n        self.b, (self.c, _) = 1, (2, 3)\n"
        f"        self.d: int = 4\n        self.b += 1\n\n"
        f"    @staticmethod\n    def other(obj):\n        obj.e = 5\n\n"
        f"class Fields:\n{fields}\n    k: ClassVar[int] = 0\n")
    assert offenders(tmp_path / "pkg") == {"pkg/m.py::long": "function: 61 lines",
                                           "pkg/m.py::Many": "class: 22 instance attributes",
                                           "pkg/m.py::Fields": "class: 21 instance attributes"}


def test_hint_checker(tmp_path):
    """Public functions and public classes' methods need hints on every parameter but self and on the return;
    private ones, nested ones and the methods of private classes do not."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text(
        "def f(a: int, *args, b=1) -> int:\n    def inner(x):\n        return x\n    return a\n\n"
        "def g(a: int) -> None:\n    pass\n\n"
        "def _h(a):\n    pass\n\n"
        "class C:\n    def __init__(self, a: int):\n        pass\n\n"
        "    @staticmethod\n    def s(a: int) -> int:\n        return a\n\n"
        "    def m(self, a: int) -> int:\n        return a\n\n"
        "class _P:\n    def m(self, a):\n        pass\n")
    assert untyped(tmp_path / "pkg") == {"pkg/m.py::f": ["b", "*args"], "pkg/m.py::C.__init__": ["return"]}


# Imports that may stand inside a function: heavy dependencies that a run imports only when it needs them. Each entry
# is a promise kept by the reason beside it (and one that no function imports any more is an error: take it out).
DEFERRED_IMPORTS: dict[str, str] = {
    "matplotlib": "figures (pfault.post, the calibration's and the scenarios' reports) and the triangle search of a "
                  "land surface (a head file on scattered points, an InSAR product's pixels): a run without them "
                  "(-pfault_figures false) never loads it",
    "gmsh": "meshing the built-in geometries and reading .msh files: a box scene does not need it",
    "flopy": "MODFLOW 6 binary heads (-pfault_heads_grid) only",
    "scipy": "material properties given as fields (field:FILE), NetCDF-3 fields, the calibration's least squares, "
             "the vertical columns of soils that remember (scipy.spatial: 0.3 s of every run's start otherwise)",
    "meshio": "the XDMF series of a run directory read back (pfault.post.rundir)",
    "h5netcdf": "the LOS raster and the GIS maps (-pfault_insar_los, -pfault_crs) and InSAR products",
    "pyproj": "a CRS: -pfault_crs, a head file's or an InSAR product's",
    "rasterio": "the GeoTIFFs of gis/ (-pfault_crs)",
    "affine": "the GeoTIFFs' geotransform, with rasterio",
}

# PETSc and MPI start when they are imported: these modules import them (or the pfault modules that do) where they
# use them, each with its reason.
PETSC_LATER: dict[str, tuple[tuple[str, ...], str]] = {
    "pfault/__main__.py": (("petsc4py", "pfault.options", "pfault.cli"),
                           "reads the command line and the scene first: petsc4py.init must see its options"),
    "pfault/errors.py": (("mpi4py",), "imported by pfault/__main__.py before petsc4py.init"),
    "pfault/io/output.py": (("petsc4py", "mpi4py"), "the versions a run records; post-processing imports the "
                                                    "module (open_h5, read_options) and starts neither"),
    "pfault/io/probes.py": (("mpi4py",), "its geometry serves the materials' fields and the GIS layers without MPI"),
    "pfault/io/parallel.py": (("mpi4py",), "its shape agreement is unit-tested without MPI "
                                           "(tests/unit/test_agree_shapes.py)"),
}


def _function_imports(root: Path) -> list[tuple[str, int, str]]:
    """(file, line, module) of every import inside a function, ``module`` with its leading dots."""
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    names = [("." * node.level) + (node.module or "")]
                else:
                    continue
                found += [(path.relative_to(root.parent).as_posix(), node.lineno, name) for name in names]
    return sorted(set(found))


def _excused(file: str, name: str) -> bool:
    later = PETSC_LATER.get(file, ((), ""))[0]
    return name.split(".")[0] in DEFERRED_IMPORTS or name in later or name.split(".")[0] in later


def inner_imports(root: Path = PACKAGE) -> list[str]:
    """Imports inside functions that are neither of DEFERRED_IMPORTS nor of PETSC_LATER: "path:line module"."""
    return [f"{file}:{line} {name}" for file, line, name in _function_imports(root) if not _excused(file, name)]


def module_imports(root: Path = PACKAGE) -> dict[str, set[str]]:
    """{module: the modules of the package it imports at its top level (outside functions; not the imports under
    ``if TYPE_CHECKING:``, which are not run)}."""
    top = root.name
    graph: dict[str, set[str]] = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        package = parts if path.name == "__init__.py" else parts[:-1]
        deps: set[str] = set()
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name.split(".")[0] == top}
            elif isinstance(node, ast.ImportFrom):
                base = package[:len(package) - node.level + 1] if node.level else []
                mod = ".".join(base + ([node.module] if node.module else [])) if node.level else (node.module or "")
                if mod.split(".")[0] != top:
                    continue
                deps.add(mod)
                deps |= {f"{mod}.{a.name}" for a in node.names}
        graph[".".join(parts)] = deps
    return {m: {d for d in deps if d in graph and d != m} for m, deps in graph.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import cycles among the package's modules: each strongly connected component of more than one module
    (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def test_no_import_inside_a_function():
    assert inner_imports() == []


def test_every_deferred_import_is_still_needed():
    found = _function_imports(PACKAGE)
    stale = [name for name in DEFERRED_IMPORTS if not any(n.split(".")[0] == name for _, _, n in found)]
    stale += [f"{file} {name}" for file, (names, _) in PETSC_LATER.items() for name in names
              if not any(f == file and (n == name or n.split(".")[0] == name) for f, _, n in found)]
    assert not stale, f"imported at the top now (or no longer at all): take them out: {stale}"


def test_no_import_cycle():
    assert cycles(module_imports()) == []


def _started_on_import(root: Path) -> dict[str, set[str]]:
    """{module: which of petsc4py and mpi4py it imports at its top level}."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        names = set()
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names.add((node.module or "").split(".")[0])
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = names & {"petsc4py", "mpi4py"}
    return out


def test_post_processing_starts_neither_petsc_nor_mpi():
    """What pfault.post imports, all the way down, imports neither petsc4py nor mpi4py at its top: figures and GIS
    layers are made from a run directory in any process, and no run-time module imports pfault.post but the run's
    top (pfault.simulation) and the tools that start runs."""
    graph, started = module_imports(), _started_on_import(PACKAGE)
    seen, todo = set(), [m for m in graph if m.startswith("pfault.post")]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo += graph[m]
    assert {m: started[m] for m in seen if started[m]} == {}
    users = {m for m, deps in graph.items() if not m.startswith("pfault.post") and any(d.startswith("pfault.post")
                                                                                       for d in deps)}
    assert users <= {"pfault.simulation", "pfault.scenarios", "pfault.io.figures.__main__"} | {
        m for m in graph if m.startswith("pfault.tools")}, users


def test_import_checkers(tmp_path):
    """The checkers on a made-up package: a cycle through a ``from . import`` and a relative import of a sibling's
    name, an import under TYPE_CHECKING that closes no cycle, an inner import of the package flagged, a deferred
    heavy dependency not, and PETSc deferred only where PETSC_LATER says."""
    pkg = tmp_path / "pfault"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n\ndef f():\n    import matplotlib\n    from . import c\n")
    (pkg / "sub" / "b.py").write_text("from ..c import thing\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nfrom pfault import a\nif TYPE_CHECKING:\n"
                              "    from .sub import b\n\ndef g():\n    from petsc4py import PETSc\n")
    graph = module_imports(pkg)
    assert graph["pfault.a"] == {"pfault.sub", "pfault.sub.b"} and graph["pfault.c"] == {"pfault", "pfault.a"}
    assert cycles(graph) == [["pfault.a", "pfault.c", "pfault.sub.b"]]
    assert inner_imports(pkg) == ["pfault/a.py:5 .", "pfault/c.py:7 petsc4py"]


def names_a_script_imports(path):
    """(module, name) of every ``from pfault... / studies... import name`` in a script (at any depth)."""
    tree = ast.parse(path.read_text())
    return [(n.module, a.name) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level == 0
            and n.module and n.module.split(".")[0] in ("pfault", "studies") for a in n.names]


def test_every_script_imports_what_exists():
    """The benchmarks, studies and test scripts run outside the suite's imports: each name they import from pfault
    or studies exists (a module moved or a function removed stopped benchmarks/wuxi_inelastic.py at its import)."""
    missing = []
    for folder in ("benchmarks", "studies", "tests/scripts"):
        for path in sorted((REPO / folder).glob("*.py")):
            for module, name in names_a_script_imports(path):
                m = importlib.import_module(module)
                submodule = hasattr(m, "__path__") and importlib.util.find_spec(f"{module}.{name}") is not None
                if not hasattr(m, name) and not submodule:
                    missing.append(f"{path.relative_to(REPO)}: from {module} import {name}")
    assert not missing, missing
