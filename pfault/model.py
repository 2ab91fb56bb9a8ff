"""The model of a run: built once from the settings, unchanged while the run goes on.

``build_model`` reads the scene (settings, materials, boundaries, faults, the pore-pressure source), builds the
mesh on rank 0 and distributes it (PETSc log stage Mesh), then the fields, the assembler, the fault interface,
the source and the equations (stage Setup). What changes during the run is ``pfault.state.State``'s.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from petsc4py import PETSc

from . import checks, fields, scene as scn
from .assembly.elastic import ElasticAssembler
from .effects import logged
from .effects import decide as decide_effects
from .errors import InputError, run_on_root, warn
from .materials import properties
from .mesh import distributed
from .solver.equations import Equations, constrained_local
from .solver.choice import AUTO, ITERATIVE_FROM_DOFS, solver_file_name
from .solver.flow import FIXED_HEAD_BIT, GroundwaterFlow, fixed_head_vertices, read_flow_settings
from .solver.setup import apply_solver_file, find_solver_file
from .sources import FlowSource, TableSource, Unchanged
from .faults.bubbles import CellBubbles
from .faults.faces import FaultFaces
from .faults.history import face_pressure
from .faults.term import FaultTerm, fault_topology
from .margins import read_margin_settings
from .mesh.fault import split_faults
from .georef import read_georef
from .sources.heads import build_heads_source, check_heads_files, read_heads_settings, read_mesh_origin
from .soils.cells import bubble_moduli, check_krylov, land_top, with_reference
from .soils.overburden import initial_effective_stress
from .soils.term import SoilTerm


@dataclass(frozen=True)
class Scene:
    """What the options ask for (every rank): settings, the names the mesh defines, the parts' settings."""
    settings: Any
    restart_dir: str | None
    figures: str                    # -pfault_figures: apart, true or false
    solver_name: str                # -pfault_solver: auto, a name or a path
    material_names: list
    surface_names: list
    materials: list
    drawdown: Any                   # per-material tables (pfault.physics.loading.MaterialDrawdown)
    flow_settings: Any              # the flow model's settings, or None
    fault_settings: list
    boundaries: list
    contact: Any                    # contact options (None without faults)
    effects: Any
    heads_settings: Any = None      # a groundwater model's heads (pfault.sources.heads.HeadsSettings), or None
    mesh_origin: tuple = (0.0, 0.0, 0.0)    # site coordinates = mesh coordinates + mesh_origin (m)
    warnings: tuple = ()            # the warning lines printed about the scene's input (summary.json keeps them)
    unchanged_materials: tuple = ()         # materials whose pore pressure does not change
    georef: Any = None              # -pfault_crs, -pfault_start_date (pfault.georef.Georef)
    margins: Any = None             # what margins to failure report (pfault.solver.terms.MarginSettings), or None
    soils: tuple = ()               # per material its law with memory (pfault.scene.Soil) or None; () with none


@dataclass(frozen=True)
class Model:
    """A run's model. ``serial`` and ``split`` (the serial mesh and its fault split) are held by rank 0 only;
    ``fault_id`` the fault of every fault face (serial order; empty without faults), ``faces`` the fault faces this
    rank owns (pfault.fields.FaceRows), ``source`` the pore-pressure
    source, ``equations`` the discrete problem with its terms (a fault interface: ``equations.terms``),
    ``solver_file`` the solver options file applied (None: none); ``properties`` the materials' properties per
    local cell (pfault.materials.properties.CellProperties)."""
    comm: Any
    scene: Scene
    serial: Any
    split: Any
    mesh: Any
    dofmap: Any
    properties: Any
    assembler: Any
    fault_id: Any
    faces: Any
    source: Any
    equations: Any
    solver_file: str | None
    wall: dict

    @property
    def settings(self) -> Any:
        return self.scene.settings

    def destroy(self) -> None:
        """Collective: every rank destroys the model at once (left to the garbage collector, which may free the
        objects on some ranks only, PETSc 3.18's PetscFinalize waits for ever in its collective cleanup)."""
        self.equations.destroy()
        self.source.destroy()
        self.dofmap.section.destroy()
        if self.mesh.migration is not None:
            self.mesh.migration.destroy()
        self.mesh.dm.destroy()


def _check_restart_dir(path: str) -> None:
    if os.path.exists(path) and not os.path.isdir(path):
        raise InputError(f"-pfault_restart {path}: is a file, not a run directory; give the output directory of "
                         "the run to continue (the directory that holds its checkpoint.h5)")
    if not os.path.isdir(path):
        raise InputError(f"-pfault_restart {path}: no such run directory")


def _check_one_pressure_source(heads: Any, drawdown: Any, flow: bool) -> None:
    """The pore pressure comes from one place: the groundwater model's heads exclude tables and the flow model."""
    if flow:
        raise InputError(f"-pfault_heads_file {heads.file}: the pore pressure comes from these heads; remove "
                         "-pfault_flow (or the head file)")
    if drawdown.active:
        raise InputError(f"-pfault_heads_file {heads.file}: the pore pressure comes from these heads; remove the "
                         "per-material head_drawdown/pressure_change tables (or the head file)")


def read_scene(comm: Any, reader: Any, options_file: str) -> tuple[Scene, Any]:
    """The scene's settings (every rank) and the serial mesh (rank 0; None elsewhere)."""
    s = scn.read_settings(reader, options_file)
    restart_dir = reader.get("pfault_restart")
    figures = reader.get("pfault_figures")
    if restart_dir:
        run_on_root(comm, _check_restart_dir, restart_dir)
        if not reader.has("pfault_output_dir"):
            # a restarted run continues in the directory of the run it continues
            s = dataclasses.replace(s, output_dir=restart_dir)
    run_on_root(comm, checks.probe_output_dir, s.output_dir)
    solver_name = reader.get("pfault_solver")
    if solver_name and solver_name != AUTO:
        find_solver_file(solver_name, options_file)         # a file that is not there: an error before meshing
    mesh_origin = read_mesh_origin(reader)
    georef = read_georef(reader, options_file)
    margins = read_margin_settings(reader, s, mesh_origin)
    heads_settings = read_heads_settings(reader, s.water_density, s.gravity, mesh_origin, options_file, georef.crs)
    if heads_settings is not None:
        run_on_root(comm, check_heads_files, heads_settings, s.time_end)     # before meshing: fail fast
    build_serial = scn.generator_options(reader, s, index_bytes=np.dtype(PETSc.IntType).itemsize)
    serial = run_on_root(comm, build_serial)
    names = comm.tompi4py().bcast((serial.material_names, sorted(serial.surfaces)) if comm.rank == 0 else None)
    material_names, surface_names = names
    scn.check_ground_surface(reader, s, surface_names)
    soils = scn.read_soils(reader, material_names, s.geostatic)
    materials = scn.read_materials(reader, material_names, soil={m.name for m in soils if m is not None})
    drawdown = scn.read_drawdown(reader, material_names, s.water_density, s.gravity)
    if heads_settings is not None:
        _check_one_pressure_source(heads_settings, drawdown, reader.get("pfault_flow"))
    flow_settings = None
    if reader.get("pfault_flow"):
        if drawdown.active:
            raise InputError("-pfault_flow: the pore pressure comes from the flow model; remove the "
                             "per-material head_drawdown/pressure_change tables")
        flow_settings = read_flow_settings(reader, material_names, materials, surface_names, s.water_density,
                                           s.gravity)
    source_given = drawdown.active or flow_settings is not None or heads_settings is not None
    unchanged = scn.read_unchanged_materials(reader, material_names, drawdown, source_given)
    fault_settings = scn.read_faults(reader, surface_names)
    fault_names = [f.name for f in fault_settings]
    boundaries = scn.read_boundaries(reader, surface_names, exclude=fault_names)
    contact = scn.read_contact_options(reader) if fault_names else None
    reader.check_pfault_options()
    warnings = tuple(warn(comm, text) for text in scn.time_table_warnings(reader, s))
    soils = tuple(soils) if any(m is not None for m in soils) else ()
    effects = decide_effects(s, materials, drawdown, flow_settings is not None, fault_settings, boundaries,
                             heads=heads_settings.file if heads_settings is not None else "", unchanged=unchanged,
                             soils=tuple(m.name for m in soils if m is not None))
    scene = Scene(s, restart_dir, figures, solver_name, material_names, surface_names,
                  materials, drawdown, flow_settings, fault_settings, boundaries, contact, effects,
                  heads_settings, mesh_origin, warnings=warnings, unchanged_materials=unchanged, georef=georef,
                  margins=margins, soils=soils)
    return scene, serial


def _field_values(scene: Scene, serial: Any, options_file: str) -> tuple[dict, list]:
    """Rank 0: the material properties given as fields, on the serial cells ({option: values}; empty without
    fields), and the notes on how their files were read (pfault.materials.field_files.SpatialField.note)."""
    refs = properties.field_refs(scene.materials, scene.flow_settings, scene.soils)
    notes: list = []
    if not refs:
        return {}, notes
    return properties.serial_field_values(scene.material_names, refs, serial.points, serial.tets,
                                          serial.cell_material, options_file, scene.mesh_origin, notes), notes


def _read_fields(comm: Any, scene: Scene, serial: Any, options_file: str) -> tuple[Scene, dict | None]:
    """The field options' values (rank 0, _field_values; None elsewhere), and the scene with their files' notes
    among its warnings (every rank; printed once)."""
    serial_values, notes = run_on_root(comm, _field_values, scene, serial, options_file) or (None, None)
    notes = comm.tompi4py().bcast(notes)
    if notes:
        scene = dataclasses.replace(scene, warnings=scene.warnings + tuple(warn(comm, text) for text in notes))
    return scene, serial_values


def _serial_arrays(scene: Scene, serial: Any, serial_values: dict) -> tuple:
    """Rank 0: the boundary arrays of the serial mesh, its fault split and the faults' topology."""
    s = scene.settings
    out = scn.boundary_arrays(serial, scene.boundaries, s.ground_surface)
    checks.check_held(serial.points, out[0], [b.name for b in scene.boundaries])
    if scene.flow_settings is not None:
        out[0][:] |= FIXED_HEAD_BIT * fixed_head_vertices(serial, scene.flow_settings.fixed_head_surfaces)
    split = topology = None
    fault_names = [f.name for f in scene.fault_settings]
    if fault_names:
        split = split_faults(serial, fault_names)
        cell = properties.CellProperties.of_cells(scene.materials, serial.cell_material, serial_values)
        if scene.soils:
            ground = out[2][:, 0] == 1
            _, cell = with_reference(cell, list(scene.soils), serial.cell_material,
                                     serial.points[serial.tets].mean(axis=1)[:, 2], land_top(serial.points, ground),
                                     s, serial_values)
        topology = fault_topology(serial, split, cell.young_modulus)
    written = 1 + s.time_steps // s.output_every + (s.time_steps % s.output_every > 0)
    checks.check_output_space(s.output_dir, checks.output_bytes(
        len(serial.points) + (len(split.copies[0]) if split else 0), len(serial.tets),
        len(split.faces) if split else 0, written, flow=scene.flow_settings is not None))
    return out, split, topology


def _source(scene: Scene, mesh: Any, props: Any, field_values: dict | None) -> Any:
    """The pore-pressure source (the flow model, a groundwater model's heads, or the per-material tables), with no
    change in the materials whose pore pressure does not change."""
    source = _given_source(scene, mesh, props, field_values)
    if not scene.unchanged_materials:
        return source
    ids = [scene.material_names.index(name) for name in scene.unchanged_materials]
    return Unchanged(source, np.isin(mesh.cell_material, ids))


def _given_source(scene: Scene, mesh: Any, props: Any, field_values: dict | None) -> Any:
    """The pore-pressure source: the flow model, a groundwater model's heads, or the per-material tables."""
    if scene.heads_settings is not None:
        with logged("pfaultHeadsRead"):
            centroids = mesh.coords[mesh.cells].mean(axis=1)
            return build_heads_source(mesh.dm.getComm(), scene.heads_settings, centroids, scene.settings.time_end)
    if scene.flow_settings is None:
        return TableSource(scene.drawdown, mesh.cell_material)
    fs, s = scene.flow_settings, scene.settings
    k, ss = properties.flow_cell_properties(fs, props, mesh.cell_material, field_values, mesh.cell_serial,
                                            s.water_density, s.gravity)
    return FlowSource(GroundwaterFlow(mesh, k, ss, wells=fs.wells,
                                      fixed_head=(mesh.vert_data[:, 0] & FIXED_HEAD_BIT) != 0,
                                      substeps=fs.substeps, water_density=s.water_density, gravity=s.gravity))


def _dofmap(scene: Scene, mesh: Any) -> Any:
    if not scene.fault_settings:
        return fields.build(mesh)
    lm_faces = (mesh.cell_fault_face >= 0).sum(axis=1)     # 3 multipliers per fault face, on its minus cell
    return fields.build(mesh, vert_sides=mesh.vert_sides, cell_side=mesh.cell_side, cell_multipliers=lm_faces)


def _apply_solver(scene: Scene, mesh: Any, options_file: str) -> str | None:
    """Apply the solver options file of -pfault_solver (pfault.solver.choice: ``auto`` takes the direct solver below
    a size, the iterative one above) where the scene and the command line are silent; returns its path."""
    # the unknowns this rank owns: the global section's (DMPlex caches it; the state's Vec is laid out from it)
    owned = mesh.dm.getGlobalSection().getConstrainedStorageSize()
    n_dofs = int(mesh.dm.getComm().tompi4py().allreduce(owned))
    name = solver_file_name(scene.solver_name or "", n_dofs, pc_type_given=PETSc.Options().hasName("pc_type"))
    if scene.solver_name == AUTO and name:
        PETSc.Sys.Print(f"pfault: -pfault_solver auto: {name} ({n_dofs:,} unknowns; the iterative solver from "
                        f"{ITERATIVE_FROM_DOFS:,})")
    return apply_solver_file(name, options_file)


def fault_terms(scene: Scene, mesh: Any, dofmap: Any, assembler: Any, cell_props: Any, topology: Any,
                soil: Any = None) -> tuple:
    """The terms the scene's faults give the equations: one fault interface for all of them (pfault.faults.term),
    none without faults. ``soil``: the cells of the materials with memory (pfault.soils.cells.SoilCells), whose
    face bubbles take the law's virgin tangent (pfault.soils.cells.bubble_moduli), or None."""
    if not scene.effects.faults:
        return ()
    with logged("pfaultFaultSetup"):
        fixed, lgmap = constrained_local(mesh, dofmap), mesh.dm.getLGMap()
        faces = FaultFaces(mesh, dofmap, scene.fault_settings, topology.fault_id, cell_props.young_modulus, fixed,
                           lgmap)
        lam, mu = (assembler.lam, assembler.mu) if soil is None else bubble_moduli(soil, assembler.lam, assembler.mu)
        bubbles = CellBubbles(faces.sides.cell, faces.sides.lface, dofmap.cell_dofs, fixed,
                              (assembler.grad, assembler.vol, lam, mu), faces.area,
                              faces.R, lgmap.apply, PETSc.IntType)
        face_z = mesh.coords[faces.verts][:, :, 2].mean(axis=1)
        pressure = face_pressure(scene.contact, scene.settings, face_z, faces.cell, assembler.alpha)
        return (FaultTerm(faces, scene.fault_settings, topology, bubbles, pressure),)


def serial_overburden(scene: Scene, serial: Any, serial_values: dict) -> np.ndarray:
    """Rank 0: the initial vertical effective stress of every cell of the materials with memory (Pa, compression
    positive; zero elsewhere), on the serial mesh: pfault.soils.overburden.initial_effective_stress."""
    cell = properties.CellProperties.of_cells(scene.materials, serial.cell_material, serial_values)
    soil = np.array([m is not None for m in scene.soils])[serial.cell_material]
    out = np.zeros(len(serial.tets))
    c = np.flatnonzero(soil)
    out[c] = initial_effective_stress(serial.points, serial.tets, c, cell.density, cell.biot_coefficient,
                                      scene.settings)
    return out


def _soil_cells(comm: Any, scene: Scene, serial: Any, mesh: Any, serial_values: dict, cell_props: Any) -> tuple:
    """The local cells of the materials with memory (pfault.soils.cells.SoilCells), the cells' properties with their
    reference modulus, and the overburden of every serial cell; (None, the properties, None) without them."""
    if not scene.soils:
        return None, cell_props, None
    with logged("pfaultSoilSetup"):
        overburden = comm.tompi4py().bcast(run_on_root(comm, serial_overburden, scene, serial, serial_values))
        z = mesh.coords[mesh.cells].mean(axis=1)[:, 2]
        top = land_top(mesh.coords, mesh.vert_data[:, 1] == 1, comm.tompi4py())
        soil, cell_props = with_reference(cell_props, list(scene.soils), mesh.cell_material, z, top, scene.settings,
                                          serial_values, mesh.cell_serial)
    return soil, cell_props, overburden


def soil_terms(soil: Any, mesh: Any, dofmap: Any, assembler: Any, overburden: np.ndarray | None) -> tuple:
    """The term of the materials with memory (pfault.soils.term), none without them; ``overburden``: the weight of
    the initial vertical effective stress of every serial cell (Pa; ``serial_overburden``)."""
    if soil is None:
        return ()
    with logged("pfaultSoilSetup"):
        c = soil.cells
        free = ~constrained_local(mesh, dofmap)
        v = mesh.dm.createGlobalVec()
        owned = v.getOwnershipRange()
        v.destroy()
        return (SoilTerm(soil, len(mesh.cells), assembler.grad[c], assembler.vol[c], dofmap.cell_dofs[c], free,
                         mesh.dm.getLGMap().apply, owned, (assembler.lam[c], assembler.mu[c]),
                         overburden[mesh.cell_serial[c]], mesh.dm.getComm().tompi4py()),)


def build_model(comm: Any, reader: Any, options_file: str) -> Model:
    """The model of the scene in ``options_file`` (with the command line's options, through ``reader``)."""
    t0 = time.perf_counter()
    stage = PETSc.Log.Stage("Mesh")
    stage.push()
    scene, serial = read_scene(comm, reader, options_file)
    PETSc.Sys.Print("pfault:", scene.effects.line())
    scene, serial_values = _read_fields(comm, scene, serial, options_file)
    arr = run_on_root(comm, _serial_arrays, scene, serial, serial_values)
    (mask, face_tag, ground), split, topology = arr if arr is not None else ((None, None, None), None, None)
    mesh = distributed.build(comm, serial, cell_face_tag=face_tag, vert_constraint=mask, vert_ground=ground,
                             split=split)
    if scene.fault_settings:
        topology = comm.tompi4py().bcast(topology if comm.rank == 0 else None)
    if comm.size > 1 and properties.field_refs(scene.materials, scene.flow_settings, scene.soils):
        serial_values = comm.tompi4py().bcast(serial_values if comm.rank == 0 else None)  # the fields' values
    cell_props = properties.CellProperties.of_cells(scene.materials, mesh.cell_material, serial_values,
                                                    mesh.cell_serial)
    soil, cell_props, overburden = _soil_cells(comm, scene, serial, mesh, serial_values, cell_props)
    stage.pop()
    wall = {"mesh": time.perf_counter() - t0}

    t0 = time.perf_counter()
    stage = PETSc.Log.Stage("Setup")
    stage.push()
    fault_id = topology.fault_id if topology is not None else np.zeros(0, np.int64)
    dofmap = _dofmap(scene, mesh)
    faces = fields.face_rows(mesh, dofmap, len(fault_id))
    solver_file = _apply_solver(scene, mesh, options_file)
    check_krylov(tuple(m.name for m in scene.soils if m is not None), PETSc.Options().getString("ksp_type", ""))
    source = None
    try:
        assembler = ElasticAssembler(mesh, dofmap, cell_props, None if soil is None else soil.elastic(len(mesh.cells)))
        source = _source(scene, mesh, cell_props, serial_values)
        terms = fault_terms(scene, mesh, dofmap, assembler, cell_props, topology, soil)
        terms += soil_terms(soil, mesh, dofmap, assembler, overburden)
        equations = Equations(mesh, dofmap, assembler, scene.boundaries, source, scene.settings, terms)
    except BaseException:
        # destroyed here, on every rank at once (the error is every rank's): left to the garbage collector,
        # which may free them on some ranks only, PETSc 3.18's PetscFinalize waits for ever
        if source is not None:
            source.destroy()
        dofmap.section.destroy()
        if mesh.migration is not None:
            mesh.migration.destroy()
        mesh.dm.destroy()
        raise
    stage.pop()
    wall["setup"] = time.perf_counter() - t0
    return Model(comm, scene, serial, split, mesh, dofmap, cell_props, assembler, fault_id, faces, source, equations,
                 solver_file, wall)
