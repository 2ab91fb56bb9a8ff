"""What a scene asks for: settings read from the options database, and the serial mesh it builds.

Only what the scene calls for is built: no fault -> no multiplier field; no geostatic stress -> no
gravity term; no drawdown table -> no pore-pressure load.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .checks import check_box_indices, check_box_memory
from .errors import InputError
from .faults.settings import ContactSettings, FaultSettings
from .mesh import cache
from .mesh.box import box_mesh, parse_planes
from .mesh.geometry import queretaro_mesh, wuxi_mesh
from .mesh.gmsh_io import read_msh
from .mesh.serial import locate_faces
from .options import SPECS, spec_for
from .physics.loading import MaterialDrawdown, Table
from .materials.properties import FieldRef, is_field
from .units import UNITS, format_duration, quantity_unit

if TYPE_CHECKING:
    from .faults.settings import ContactSettings, FaultSettings
    from .mesh.serial import SerialMesh
    from .options import OptionReader


@dataclass(frozen=True)
class Material:
    """A material's properties as its options give them: a number (SI), or a field
    (pfault.materials.properties.FieldRef) interpolated at the cells' centroids; the model turns them into per-cell
    arrays (pfault.materials.properties)."""
    name: str
    young_modulus: float | FieldRef | None          # None: a material with memory (pfault.physics.soil)
    poisson_ratio: float | FieldRef
    biot_coefficient: float | FieldRef
    density: float | FieldRef


@dataclass(frozen=True)
class Boundary:
    name: str
    kind: str            # free | fixed | roller | traction | displacement
    traction: tuple = (0.0, 0.0, 0.0)
    displacement: tuple = (0.0, 0.0, 0.0)
    components: int = 0  # bit mask of prescribed components (type displacement)
    history: Table | None = None  # Table of a scale factor, or None for constant 1

    def scale(self, t: float) -> float:
        return 1.0 if self.history is None else self.history(t)


@dataclass(frozen=True)
class Settings:
    scene: str
    output_dir: str
    output_every: int
    ground_surface: str
    mesh_file: str
    mesh_generator: str
    time_end: float
    time_steps: int
    geostatic: bool
    k0: float            # K0_UNSET: nu/(1-nu) of each material
    gravity: float
    water_density: float
    water_table: float
    max_cuts: int = 3
    hazard_strain_threshold: float = 2e-4
    geostatic_stress: str = "gravity"   # the initial vertical stress: gravity (the elastic solve) | lithostatic


# the solver reads a negative K0 as "not given"; users cannot give one (read_settings rejects it)
K0_UNSET = -1.0


def read_settings(reader: OptionReader, options_file: str = "") -> Settings:
    stem = os.path.splitext(os.path.basename(options_file))[0] if options_file else "scene"
    scene = reader.get("pfault_scene") or stem
    out = reader.get("pfault_output_dir")
    if out == "runs/<scene>":
        out = os.path.join("runs", scene)
    if not out.strip():
        raise InputError("-pfault_output_dir: empty directory name; give a directory such as runs/<scene>")
    every = reader.get("pfault_output_every")
    if every < 1:
        raise InputError(f"-pfault_output_every: must be at least 1 (fields every N steps), got {every}")
    if reader.has("pfault_geostatic_stress") and not reader.get("pfault_geostatic"):
        raise InputError("-pfault_geostatic_stress: sets the initial stress of a geostatic start; add "
                         "-pfault_geostatic true or remove it")
    k0 = reader.get("pfault_geostatic_k0")
    if k0 is not None and k0 < 0:
        raise InputError(f"-pfault_geostatic_k0: must not be negative, got {k0:g} (leave it unset for "
                         "nu/(1-nu))")
    s = Settings(scene=scene, output_dir=out, output_every=every,
                 ground_surface=reader.get("pfault_ground_surface"), mesh_file=reader.get("pfault_mesh_file"),
                 mesh_generator=reader.get("pfault_mesh_generator"), time_end=reader.get("pfault_time_end"),
                 time_steps=reader.get("pfault_time_steps"), geostatic=reader.get("pfault_geostatic"),
                 k0=K0_UNSET if k0 is None else k0, gravity=reader.get("pfault_gravity"),
                 water_density=reader.get("pfault_water_density"), water_table=reader.get("pfault_water_table"),
                 max_cuts=reader.get("pfault_time_max_cuts"),
                 geostatic_stress=reader.get("pfault_geostatic_stress"),
                 hazard_strain_threshold=reader.get("pfault_hazard_strain_threshold"))
    if not s.hazard_strain_threshold > 0:
        raise InputError(f"-pfault_hazard_strain_threshold: must be positive, got {s.hazard_strain_threshold:g} "
                         "(e.g. 2e-4 for 0.02 %)")
    if s.max_cuts < 0 or s.max_cuts > 10:
        raise InputError(f"-pfault_time_max_cuts: give 0 to 10 halvings, got {s.max_cuts}")
    if s.time_steps < 1:
        raise InputError("-pfault_time_steps: need at least one step")
    if s.time_end <= 0:
        raise InputError("-pfault_time_end: must be positive (e.g. 10*year)")
    return s


def generator_options(reader: OptionReader, settings: Settings, index_bytes: int = 4) -> Callable[[], SerialMesh]:
    """Read the options of the built-in generator; returns a callable building the SerialMesh on rank 0.
    ``index_bytes``: size of PETSc's indices, which bounds the number of unknowns of a box. -pfault_mesh_cache is
    read for every scene (a place on this machine, like a cache directory: a scene whose mesh is not generated by
    gmsh leaves it unused without an error)."""
    reader.get("pfault_mesh_cache")
    if settings.mesh_file:
        path = settings.mesh_file
        return lambda: read_msh(path)
    if settings.mesh_generator == "box":
        size = reader.get("pfault_box_size")
        cells = reader.get("pfault_box_cells")
        mats = reader.get("pfault_box_materials")
        interfaces = reader.get("pfault_box_interfaces")
        if len(size) != 3 or len(cells) != 3:
            raise InputError("-pfault_box_size and -pfault_box_cells take three values each (x,y,z)")
        if min(size) <= 0:
            raise InputError(f"-pfault_box_size: lengths must be positive, got {','.join(f'{v:g}' for v in size)}")
        if min(cells) < 1:
            raise InputError(f"-pfault_box_cells: need at least one cell per direction, got "
                             f"{','.join(str(c) for c in cells)}")
        check_box_indices(cells, index_bytes)
        planes = parse_planes(reader.get("pfault_box_fault_planes"))

        def build_box():
            check_box_memory(cells)
            return box_mesh(size, cells, mats, interfaces, planes=planes)
        return build_box
    if settings.mesh_generator == "wuxi":
        factor = reader.get("pfault_mesh_size_factor")
        params = {key: reader.get(f"pfault_wuxi_{key}") for key in
                  ("ridge_x", "crest_depth", "bedrock_depth", "ridge_half_width", "interfaces")}
        return _cached(reader, "wuxi", factor, params, wuxi_mesh)
    if settings.mesh_generator == "queretaro":
        factor = reader.get("pfault_mesh_size_factor")
        params = {key: reader.get(f"pfault_queretaro_{key}") for key in ("fault_x", "clay_thickness", "wells",
                                                                             "fault_size", "surface_size",
                                                                             "layer_thickness")}
        if not reader.has("pfault_queretaro_wells") and reader.has("pfault_flow_wells"):
            # refine where the flow model pumps
            params["wells"] = reader.get("pfault_flow_wells")
        return _cached(reader, "queretaro", factor, params, queretaro_mesh)
    raise InputError(f"-pfault_mesh_generator {settings.mesh_generator}: this generator is not available yet; "
                     "use box, wuxi or queretaro, or give -pfault_mesh_file")


def _cached(reader: OptionReader, generator: str, factor: float, params: dict,
            mesh: Callable[..., SerialMesh]) -> Callable[[], SerialMesh]:
    """The build of a gmsh generator's mesh through the mesh cache of -pfault_mesh_cache (pfault.mesh.cache): its
    key is the generator, the options as read and the generator's code version."""
    directory = reader.get("pfault_mesh_cache")
    if not reader.has("pfault_mesh_cache"):
        directory = cache.default_dir()
    elif directory != cache.NONE:
        directory = os.path.expanduser(directory)
    return lambda: cache.cached_mesh(directory, cache.mesh_key(generator, {"size_factor": factor, **params}),
                                     lambda: mesh(factor, **params))


def check_ground_surface(reader: OptionReader, settings: Settings, surface_names: Collection[str]) -> None:
    """The land surface is a surface of the mesh; only the default 'top' may be missing (then subsidence
    is measured over all vertices)."""
    name = settings.ground_surface
    if name in surface_names or (name == "top" and not reader.has("pfault_ground_surface")):
        return
    raise InputError(f"-pfault_ground_surface {name}: no such physical surface in the mesh; give one of "
                     f"{', '.join(surface_names) or '(none: the mesh has no physical surfaces)'}")


def read_materials(reader: OptionReader, names: Iterable[str], soil: Collection[str] = ()) -> list[Material]:
    """The materials' properties; a number is checked here, a field's values when its file is read. The materials
    named in ``soil`` have a law with memory (``read_soils``) and no drained modulus (None)."""
    mats = []
    for name in names:
        p = f"pfault_material_{name}_"
        e = reader.get(p + "young_modulus") if name not in soil else None
        nu = reader.get(p + "poisson_ratio")
        if e is None and name not in soil:
            raise InputError(f"missing -{p}young_modulus (Pa) for physical volume '{name}'")
        if nu is None:
            raise InputError(f"missing -{p}poisson_ratio for physical volume '{name}'")
        if e is not None and not is_field(e) and not e > 0:
            raise InputError(f"-{p}young_modulus: must be positive, got {e}")
        if not is_field(nu) and not -1.0 < nu < 0.5:
            raise InputError(f"-{p}poisson_ratio: must lie in (-1, 0.5), got {nu}")
        alpha = reader.get(p + "biot_coefficient")
        if not is_field(alpha) and not 0.0 <= alpha <= 1.0:
            raise InputError(f"-{p}biot_coefficient: must lie in [0, 1], got {alpha}")
        rho = reader.get(p + "density")
        if not is_field(rho) and not rho > 0:
            raise InputError(f"-{p}density: must be positive, got {rho}")
        mats.append(Material(name, e, nu, alpha, rho))
    return mats


@dataclass(frozen=True)
class Soil:
    """A material with memory (pfault.physics.soil) as its options give it, numbers (SI) or fields: the
    compression-index form (Cc, Cr, e0) or CSUB's head-based storage form (Sske, Sskv, 1/m), and its preconsolidation:
    normal (normally consolidated), stress (sigma'_vc, Pa), ratio (OCR) or head (m, relative to the initial heads)."""
    name: str
    form: str                                        # index | storage
    compression: float | FieldRef                    # Cc, or Sskv
    recompression: float | FieldRef                  # Cr, or Sske
    void_ratio: float | FieldRef | None              # e0 (index form)
    preconsolidation: str = "normal"                 # normal | stress | ratio | head
    preconsolidation_value: float | FieldRef | None = None


SOIL_FORMS = {"index": ("compression_index", "recompression_index"),
              "storage": ("inelastic_skeletal_specific_storage", "elastic_skeletal_specific_storage")}
PRECONSOLIDATION = {"stress": "preconsolidation_stress", "ratio": "overconsolidation_ratio",
                    "head": "preconsolidation_head"}


def read_soils(reader: OptionReader, names: Iterable[str], geostatic: bool) -> list[Soil | None]:
    """Per material its law with memory, or None: a material given none of these options stays linear elastic."""
    return [_read_soil(reader, name, geostatic) for name in names]


def _read_soil(reader: OptionReader, name: str, geostatic: bool) -> Soil | None:
    p = f"pfault_material_{name}_"
    given = {form: [reader.has(p + key) for key in keys] for form, keys in SOIL_FORMS.items()}
    precon = [kind for kind, key in PRECONSOLIDATION.items() if reader.has(p + key)]
    forms = [form for form, flags in given.items() if any(flags)]
    if not forms:
        if precon:
            raise InputError(f"-{p}{PRECONSOLIDATION[precon[0]]}: '{name}' has no law with memory; give "
                             f"-{p}compression_index and -{p}recompression_index (or CSUB's skeletal storages), or "
                             "remove it")
        return None
    if len(forms) > 1:
        raise InputError(f"-{p}compression_index and -{p}inelastic_skeletal_specific_storage: '{name}' takes the "
                         "compression indices or CSUB's head-based skeletal storages, not both; keep one form")
    form = forms[0]
    first, second = SOIL_FORMS[form]
    for key, flag in zip(SOIL_FORMS[form], given[form]):
        if not flag:
            other = second if key == first else first
            raise InputError(f"missing -{p}{key} for '{name}', which has -{p}{other}: give both")
    if reader.has(p + "young_modulus"):
        raise InputError(f"-{p}young_modulus: '{name}' has -{p}{first}, whose stiffness follows from it and the "
                         f"effective stress; remove the drained modulus (or the {form} law)")
    if form == "index" and not reader.has(p + "void_ratio"):
        raise InputError(f"missing -{p}void_ratio for '{name}': the initial void ratio e0 of its compression-index "
                         "law (e.g. from the oedometer report)")
    if not geostatic:
        raise InputError(f"-{p}{first}: a material with memory starts from the initial effective stress; set "
                         "-pfault_geostatic true")
    compression, recompression = reader.get(p + first), reader.get(p + second)
    e0 = reader.get(p + "void_ratio") if form == "index" else None
    _check_soil_numbers(p, form, compression, recompression, e0)
    return Soil(name, form, compression, recompression, e0, *_read_preconsolidation(reader, p, name, precon))


def _check_soil_numbers(p: str, form: str, compression: float | FieldRef, recompression: float | FieldRef,
                        e0: float | FieldRef | None) -> None:
    """Ranges of the numbers (a field's values are checked when its file is read: pfault.materials.properties.RANGES)."""
    first, second = SOIL_FORMS[form]
    for key, v in ((first, compression), (second, recompression), ("void_ratio", e0)):
        if v is not None and not is_field(v) and not v > 0:
            raise InputError(f"-{p}{key}: must be positive, got {v:g}")
    if not is_field(compression) and not is_field(recompression) and not recompression < compression:
        words = ("the recompression (swelling) index is the smaller, typically Cc/10 to Cc/5" if form == "index" else
                 "the elastic skeletal storage is the smaller, typically Sskv/50 to Sskv/10")
        raise InputError(f"-{p}{second}: {recompression:g} is not below -{p}{first} {compression:g}; {words}")


def _read_preconsolidation(reader: OptionReader, p: str, name: str,
                           kinds: list[str]) -> tuple[str, float | FieldRef | None]:
    if not kinds:
        return "normal", None
    if len(kinds) > 1:
        raise InputError(f"-{p}{PRECONSOLIDATION[kinds[0]]} and -{p}{PRECONSOLIDATION[kinds[1]]}: give one "
                         f"preconsolidation for '{name}'")
    kind = kinds[0]
    key = PRECONSOLIDATION[kind]
    v = reader.get(p + key)
    if is_field(v):
        return kind, v
    if kind == "stress" and not v > 0:
        raise InputError(f"-{p}{key}: must be positive, got {v:g} (a vertical effective stress, e.g. 300*kPa)")
    if kind == "ratio" and not v >= 1:
        raise InputError(f"-{p}{key}: {v:g} is below 1, a preconsolidation below the current stress; give 1 "
                         "(normally consolidated) or more")
    if kind == "head" and not v <= 0:
        raise InputError(f"-{p}{key}: {v:g} m lies above the initial heads, a preconsolidation below the current "
                         "stress; give 0 (normally consolidated) or the lowest head before as a negative value, "
                         "e.g. -5*m")
    return kind, v


def soil_cell_message(soil: Soil, compression: np.ndarray, recompression: np.ndarray,
                      below_initial: np.ndarray) -> str | None:
    """The first problem of a material with memory on its cells, once its fields are interpolated and its initial
    stress is known (None if none): a recompression index (or elastic storage) not below the compression one, or cells
    whose preconsolidation lies below their initial vertical effective stress (``below_initial``,
    pfault.physics.soil.below_initial). Numbers were checked when read; this catches fields and depth profiles."""
    p = f"pfault_material_{soil.name}_"
    first, second = SOIL_FORMS[soil.form]
    bad = ~(np.asarray(recompression) < np.asarray(compression))
    if np.any(bad):
        return (f"-{p}{second}: not below -{p}{first} in {int(bad.sum())} of {bad.size} cells of '{soil.name}'; fix "
                "the values or the fields (the recompression is the smaller)")
    n = int(np.count_nonzero(below_initial))
    if n == 0:
        return None
    if soil.preconsolidation == "normal":
        return (f"-{p}{first}: {n} of {len(below_initial)} cells of '{soil.name}' have no initial compression (no "
                "effective stress at the start); check -pfault_geostatic and the water table")
    key = PRECONSOLIDATION[soil.preconsolidation]
    return (f"-{p}{key}: {n} of {len(below_initial)} cells of '{soil.name}' start above their preconsolidation (a "
            "preconsolidation below the current stress); raise it, give a depth profile (field:FILE), or give "
            f"-{p}overconsolidation_ratio or -{p}preconsolidation_head, which follow the initial stress")


def read_drawdown(reader: OptionReader, names: Iterable[str], water_density: float,
                  gravity: float) -> MaterialDrawdown:
    tables: list[Table | None] = []
    for name in names:
        p = f"pfault_material_{name}_"
        head = reader.get(p + "head_drawdown")
        dp = reader.get(p + "pressure_change")
        if head is not None and dp is not None:
            raise InputError(f"-{p}head_drawdown and -{p}pressure_change are both set; give one")
        if head is not None:
            tables.append(Table.from_pairs(head, scale=-water_density * gravity))
        elif dp is not None:
            tables.append(Table.from_pairs(dp))
        else:
            tables.append(None)
    return MaterialDrawdown(tables)


def time_table_warnings(reader: OptionReader, settings: Settings) -> list[str]:
    """Warnings about the time tables read so far (every table option: pore-pressure tables, boundary
    histories, well rates) that the run's time grid does not see as they were likely meant. A table holds its
    first value before its first time and its last after its last time (pfault.physics.loading.Table), which is
    what a table that ends inside the run is for (pumping, then a pause); but one that ends before the first
    step changes only where no step looks (its times in bare seconds under a run in years, the unit left out),
    and a run in bare seconds that ends before a table in years reaches its second time sees almost none of
    it (the unit left out of -pfault_time_end)."""
    end_text = reader.raw("pfault_time_end") or ""
    out = []
    for name, pairs in sorted(reader.resolved.items()):
        spec = spec_for(name)
        if spec is None or spec.kind != "table" or not pairs:
            continue
        line = table_warning(name, reader.raw(name) or "", pairs, settings.time_end, settings.time_steps, end_text)
        if line:
            out.append(line)
    return out


def table_warning(name: str, text: str, pairs: Sequence[tuple], end: float, steps: int,
                  end_text: str = "") -> str | None:
    """The warning about the table of option ``name`` (``text`` as given, ``pairs`` (time in s, value)) in a run
    of ``steps`` equal steps to ``end`` s (-pfault_time_end as given: ``end_text``), or None."""
    if len({v for _, v in pairs}) < 2:
        return None         # constant: nothing of it happens at one time rather than another
    first, end_unit = end / steps, quantity_unit(end_text)
    units = {quantity_unit(item.split(":")[0]) for item in text.split(",") if ":" in item}
    units.discard(None)
    bare = not units - {"s", "second"}              # its times are in seconds, with or without saying so
    end_bare = end_unit in (None, "s", "second")
    t_last = pairs[-1][0]
    if t_last < first * (1.0 - 1e-9):
        hint = (f"; its times have no unit, so they are seconds: give them in the run's unit (e.g. "
                f"{t_last:g}*{_closest_unit(t_last, end) if end_bare else end_unit})" if bare
                else "; check its times, or give more steps (-pfault_time_steps)")
        return (f"-{name}: the table ends at t = {format_duration(t_last)}, before the run's first step (t = "
                f"{format_duration(first)}): every step takes its last value and the run sees none of its "
                f"changes{hint}")
    t_second = pairs[1][0] if len(pairs) > 1 else t_last
    if end_bare and not bare and end < t_second:
        unit = sorted(units - {"s", "second"})[0]
        return (f"-pfault_time_end {end_text.strip() or f'{end:g} (the default)'} has no unit, so it is in seconds, "
                f"and the run ends before -{name} reaches its second time ({format_duration(t_second)}); give "
                f"-pfault_time_end a unit (e.g. {end:g}*{unit})")
    return None


def _closest_unit(t: float, end: float) -> str:
    """The time unit that makes ``t`` of it nearest (logarithmically) to the run's length ``end``."""
    names = ("minute", "hour", "day", "year")
    return min(names, key=lambda u: abs(np.log(max(t, 1e-300) * UNITS[u][0] / end)))


def check_no_fault_boundaries(reader: OptionReader, fault_names: Iterable[str]) -> None:
    """A surface that is a fault has no boundary conditions: a fault is an interior surface (cells on both sides,
    split and held by contact), boundary conditions act on the outer boundary; options for both say the scene
    names the wrong surface in one of them."""
    keys = [s.name[len("pfault_bc_<surface>_"):] for s in SPECS if s.name.startswith("pfault_bc_<surface>_")]
    for name in fault_names:
        given = [f"-pfault_bc_{name}_{k}" for k in keys if reader.has(f"pfault_bc_{name}_{k}")]
        if given:
            raise InputError(f"-pfault_faults: '{name}' is a fault and has boundary conditions ({', '.join(given)}); "
                             "a fault must be an interior surface of the mesh, boundary conditions act on its outer "
                             f"boundary: remove '{name}' from -pfault_faults or remove its -pfault_bc_{name}_* "
                             "options")


def read_unchanged_materials(reader: OptionReader, names: Sequence[str], drawdown: MaterialDrawdown,
                             source_given: bool) -> tuple[str, ...]:
    """The materials whose pore pressure does not change (-pfault_pore_pressure_unchanged_materials): materials of
    the mesh, none with a pressure table of its own, in a scene whose pore pressure changes (``source_given``)."""
    opt = "pfault_pore_pressure_unchanged_materials"
    given = tuple(dict.fromkeys(reader.get(opt)))
    for name in given:
        if name not in names:
            raise InputError(f"-{opt}: '{name}' is not a material of the mesh (materials: {', '.join(names)})")
        if drawdown.tables[list(names).index(name)] is not None:
            raise InputError(f"-{opt}: {name} has a head_drawdown or pressure_change table of its own; remove it "
                             "from the list or remove its table")
    if given and not source_given:
        raise InputError(f"-{opt}: the scene changes no pore pressure (no head_drawdown or pressure_change table, "
                         "-pfault_flow or -pfault_heads_file); remove the option")
    return given


def read_boundaries(reader: OptionReader, surface_names: Iterable[str],
                    exclude: Collection[str] = ()) -> list[Boundary]:
    """The boundary conditions of the surfaces ``surface_names`` but those in ``exclude`` (the faults, which may
    have none: check_no_fault_boundaries)."""
    check_no_fault_boundaries(reader, [n for n in surface_names if n in exclude])
    bcs = []
    for name in surface_names:
        if name in exclude:
            continue
        p = f"pfault_bc_{name}_"
        kind = reader.get(p + "type")
        traction = tuple(reader.get(p + "traction")) if kind in ("traction", "displacement") else (0.0, 0.0, 0.0)
        if len(traction) != 3:
            raise InputError(f"-{p}traction: give three components tx,ty,tz (Pa)")
        disp, comps = (0.0, 0.0, 0.0), 0
        if kind == "displacement":
            disp = tuple(reader.get(p + "displacement"))
            if len(disp) != 3:
                raise InputError(f"-{p}displacement: give three components ux,uy,uz (m)")
            for c in reader.get(p + "components"):
                if c not in ("x", "y", "z"):
                    raise InputError(f"-{p}components: '{c}' is not one of x, y, z")
                comps |= 1 << "xyz".index(c)
        history = None
        if kind in ("traction", "displacement"):
            pairs = reader.get(p + "history")
            history = Table.from_pairs(pairs) if pairs is not None else None
        bcs.append(Boundary(name, kind, traction, disp, comps, history))
    return bcs


def boundary_arrays(serial: SerialMesh, bcs: Sequence[Boundary],
                    ground_surface: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-vertex constraint masks, per-cell face tags and ground flags on the serial mesh.

    A roller fixes the displacement component normal to its surface, which must be a coordinate plane.
    """
    nv, nc = len(serial.points), len(serial.tets)
    mask = np.zeros(nv, dtype=np.int64)
    face_tag = np.full((nc, 4), -1, dtype=np.int64)
    disp_surface = np.full(nv, -1, dtype=np.int64)
    for idx, bc in enumerate(bcs):
        tri = serial.surfaces[bc.name]
        if len(tri) == 0:
            continue
        if bc.kind == "fixed":
            mask[np.unique(tri)] |= 7
        elif bc.kind == "roller":
            x = serial.points[tri]
            n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
            n /= np.linalg.norm(n, axis=1)[:, None]
            axis = int(np.argmax(np.abs(n).sum(axis=0)))
            if np.any(np.abs(np.abs(n[:, axis]) - 1.0) > 1e-6):
                raise InputError(f"-pfault_bc_{bc.name}_type roller: surface '{bc.name}' is not a coordinate "
                                 "plane; rollers need a surface normal to x, y or z")
            mask[np.unique(tri)] |= 1 << axis
        if bc.kind == "displacement":
            v = np.unique(tri)
            mask[v] |= bc.components
            disp_surface[v] = idx
        if bc.kind in ("traction", "displacement") and any(bc.traction):
            t, cell, lface = locate_faces(serial.tets, nv, tri)
            if len(t) != len(tri) or len(np.unique(t)) != len(tri):
                raise InputError(f"-pfault_bc_{bc.name}_type {bc.kind}: surface '{bc.name}' is not on the "
                                 "outer boundary of the mesh")
            face_tag[cell, lface] = idx
    ground = np.zeros(nv, dtype=np.int64)
    if ground_surface in serial.surfaces:
        ground[np.unique(serial.surfaces[ground_surface])] = 1
    else:
        ground[:] = 1
    return mask, face_tag, np.column_stack([ground, disp_surface])


def read_faults(reader: OptionReader, surface_names: Collection[str]) -> list[FaultSettings]:
    names = reader.get("pfault_faults")
    faults = []
    for name in names:
        if name not in surface_names:
            raise InputError(f"-pfault_faults: '{name}' is not a physical surface of the mesh "
                             f"(surfaces: {', '.join(surface_names)})")
        p = f"pfault_fault_{name}_"
        phi = reader.get(p + "friction_angle")
        if not 0.0 <= phi < 90.0:
            raise InputError(f"-{p}friction_angle: must lie in [0, 90) degrees, got {phi}")
        c = reader.get(p + "cohesion")
        if c < 0:
            raise InputError(f"-{p}cohesion: must not be negative, got {c}")
        strength, residual = reader.get(p + "tensile_strength"), reader.get(p + "residual_cohesion")
        if strength < 0:
            raise InputError(f"-{p}tensile_strength: must not be negative (0: a pre-existing fault), got {strength}")
        if not 0.0 <= residual <= c:
            raise InputError(f"-{p}residual_cohesion: must lie in [0, the cohesion {c:g} Pa] (-{p}cohesion), "
                             f"got {residual}")
        if residual > 0 and strength == 0:
            raise InputError(f"-{p}residual_cohesion: a pre-existing fault (no -{p}tensile_strength) has only its "
                             "cohesion; give the tensile strength of its intact surface or remove the option")
        method = reader.get(p + "method")
        faults.append(FaultSettings(name=name, cohesion=c, friction_angle=phi, method=method,
                                    tensile_strength=strength, residual_cohesion=residual,
                                    tension_cutoff=reader.get(p + "tension_cutoff"),
                                    penalty_normal=reader.get(p + "penalty_normal") if method == "penalty" else 0.0,
                                    penalty_tangential=reader.get(p + "penalty_tangential")
                                    if method == "penalty" else 0.0))
    return faults


def read_contact_options(reader: OptionReader) -> ContactSettings:
    return ContactSettings(effective_stress=reader.get("pfault_contact_effective_stress"),
                           suction=reader.get("pfault_contact_suction"),
                           monitor=reader.get("pfault_contact_monitor"))
