"""Typed application options read from the PETSc options database under ``-pfault_``.

Every option pfault reads is declared here with its type, default, unit and meaning, so that
``python -m pfault -help`` can list them and a misspelled ``-pfault_`` option is an error. Options
whose name holds a mesh name (``<material>``, ``<surface>``, ``<fault>``) are declared as patterns.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

from .errors import InputError, collective_check, exit_code_table
from .materials.properties import FIELD_PREFIX, parse_field
from .petsc_compat import options_left
from .units import parse_list, parse_quantity, parse_table


@dataclass(frozen=True)
class Spec:
    name: str            # without the leading '-', may contain <material>, <surface>, <fault>
    kind: str            # string | choice | real | int | ints | bool | quantity | property | list | table | names
    default: object
    unit: str
    help: str
    choices: tuple = ()


def _s(*args, **kw):
    return Spec(*args, **kw)


SPECS = [
    # scene
    _s("pfault_scene", "string", "", "", "scene name written to summary.json (default: options file stem)"),
    _s("pfault_output_dir", "string", "runs/<scene>", "", "directory a run writes to"),
    _s("pfault_output_every", "int", 1, "", "write fields every N time steps (the last step always)"),
    _s("pfault_ground_surface", "string", "top", "", "physical surface that is the land surface (subsidence is "
       "measured there; all vertices if the mesh has no such surface)"),
    # mesh
    _s("pfault_mesh_file", "string", "", "", "gmsh MSH 4.1 mesh; physical volumes are materials, physical "
       "surfaces are boundaries and faults, addressed by name"),
    _s("pfault_mesh_generator", "choice", "box", "", "built-in mesh when no -pfault_mesh_file is given",
       choices=("box", "wuxi", "queretaro")),
    _s("pfault_box_size", "list", "1000,1000,100", "m", "box lengths Lx,Ly,Lz; the box spans "
       "[0,Lx]x[0,Ly]x[-Lz,0], land surface at z = 0"),
    _s("pfault_box_cells", "ints", "10,10,10", "", "hexahedra per direction nx,ny,nz (6 tetrahedra each)"),
    _s("pfault_box_materials", "names", "soil", "", "material names from the top layer down"),
    _s("pfault_box_interfaces", "list", "", "m", "depths below the surface of the interfaces between the "
       "layers of -pfault_box_materials (one fewer than materials)"),
    _s("pfault_mesh_cache", "string", "~/.cache/pfault/meshes", "", "directory where the meshes of the wuxi and "
       "queretaro generators are kept between runs, each under the SHA-256 of its options and the generator's code "
       "version, so that gmsh meshes a geometry once (default: $XDG_CACHE_HOME/pfault/meshes when set); none: mesh "
       "every run"),
    _s("pfault_mesh_size_factor", "real", 1.0, "", "element size multiplier of the built-in case-study meshes "
       "(2: ~8x fewer cells; ~4x at wuxi, whose thin layers bound the element height)"),
    _s("pfault_wuxi_ridge_x", "quantity", 1000.0, "m", "wuxi: x of the bedrock ridge crest and of the vertical "
       "fissure plane (domain 2 km x 5 km x 250 m)"),
    _s("pfault_wuxi_crest_depth", "quantity", 5.0, "m", "wuxi: depth of the bedrock crest below the land "
       "surface; the fissure spans the surface down to it"),
    _s("pfault_wuxi_bedrock_depth", "quantity", 100.0, "m", "wuxi: depth of the bedrock top away from the "
       "ridge"),
    _s("pfault_wuxi_ridge_half_width", "quantity", 100.0, "m", "wuxi: horizontal distance from the crest to "
       "the foot of each (planar) ridge flank"),
    _s("pfault_wuxi_interfaces", "list", "20,50,80", "m", "wuxi: depths of the interfaces between the "
       "Quaternary layers, alternately clay and sand from the top (clay 0-20, sand 20-50, clay 50-80, "
       "sand 80-bedrock)"),
    _s("pfault_queretaro_fault_x", "quantity", 10000.0, "m", "queretaro: x of the vertical fault; rock for "
       "x below it (domain 30 km x 30 km x 50 m)"),
    _s("pfault_queretaro_clay_thickness", "quantity", 20.0, "m", "queretaro: clay aquitard thickness over "
       "the sand aquifer (down to 50 m)"),
    _s("pfault_queretaro_fault_size", "quantity", 52.0, "m", "queretaro: element size along and across the "
       "fault at size factor 1 (times -pfault_mesh_size_factor); 52 m gives the paper's 8,074 fault faces, the "
       "layers' 50/7 m elements as wide as high beside the fault, which the fault's slip needs to converge "
       "(docs/verification.md, calibrated Queretaro)"),
    _s("pfault_queretaro_layer_thickness", "quantity", None, "m", "queretaro: height of the mesh's horizontal "
       "layers of elements at size factor 1 (times -pfault_mesh_size_factor), in [0.1, 50] m, rounded to whole "
       "layers in the clay and in the sand (default 50/7 m: 3 layers in the 20 m clay, 4 in the 30 m sand)"),
    _s("pfault_queretaro_surface_size", "quantity", None, "m", "queretaro: element height at the land surface "
       "at size factor 1 (times -pfault_mesh_size_factor), in [0.1, the layer thickness] m; the layers below grow "
       "by 0.5 m per metre of depth to -pfault_queretaro_layer_thickness: thin rows of fault faces under the land "
       "surface, which the fault's answer needs to converge (docs/verification.md, calibrated Queretaro; default: "
       "uniform layers)"),
    _s("pfault_queretaro_wells", "list", "12000,12000,12000,15000,12000,18000", "m", "queretaro: well "
       "positions x1,y1,x2,y2,... in the aquifer; the mesh is refined around them (default: -pfault_flow_wells "
       "when given)"),
    _s("pfault_box_fault_planes", "names", "", "m", "internal surfaces of the box as name:axis:value, "
       "optionally limited to a rectangle name:axis:value:lo1:hi1:lo2:hi2 of the other two coordinates"),
    # materials
    _s("pfault_material_<material>_young_modulus", "property", None, "Pa", "drained Young's modulus (required)"),
    _s("pfault_material_<material>_poisson_ratio", "property", None, "", "drained Poisson ratio (required)"),
    _s("pfault_material_<material>_biot_coefficient", "property", 1.0, "", "Biot coefficient alpha"),
    _s("pfault_material_<material>_density", "property", 2000.0, "kg/m**3", "bulk (saturated) density, used "
       "by the geostatic initial stress"),
    # materials with memory (pfault.physics.soil): compression indices or CSUB's head-based skeletal storage, instead
    # of the drained modulus; declared before _specific_storage, whose suffix the storages share
    _s("pfault_material_<material>_compression_index", "property", None, "", "compression index Cc, the slope of "
       "the virgin line e - log10(sigma'_v): the material remembers its preconsolidation (with _recompression_index "
       "and _void_ratio, instead of _young_modulus; needs -pfault_geostatic true)"),
    _s("pfault_material_<material>_recompression_index", "property", None, "", "recompression (swelling) index Cr "
       "< Cc, the slope of the unloading-reloading line e - log10(sigma'_v)"),
    _s("pfault_material_<material>_inelastic_skeletal_specific_storage", "property", None, "1/m", "inelastic "
       "skeletal specific storage Sskv (MODFLOW CSUB's SSV with HEAD_BASED): an oedometric column of thickness b "
       "compacts by Sskv b dh past its preconsolidation head (with _elastic_skeletal_specific_storage, instead of "
       "_young_modulus or the indices; needs -pfault_geostatic true)"),
    _s("pfault_material_<material>_elastic_skeletal_specific_storage", "property", None, "1/m", "elastic skeletal "
       "specific storage Sske < Sskv (CSUB's SSE): compaction Sske b dh above the preconsolidation head"),
    _s("pfault_material_<material>_preconsolidation_stress", "property", None, "Pa", "preconsolidation of a "
       "material with memory: the largest vertical effective stress it has borne, at least the initial one "
       "(default: normally consolidated, the initial stress)"),
    _s("pfault_material_<material>_overconsolidation_ratio", "property", None, "", "preconsolidation as OCR >= 1, "
       "the preconsolidation over the initial vertical effective stress (instead of _preconsolidation_stress)"),
    _s("pfault_material_<material>_preconsolidation_head", "property", None, "m", "preconsolidation as the lowest "
       "head before, relative to the initial heads: 0 or negative, e.g. -5*m (CSUB's PCS0 with "
       "INITIAL_PRECONSOLIDATION_HEAD; instead of _preconsolidation_stress)"),
    _s("pfault_material_<material>_head_drawdown", "table", None, "m", "drawdown of hydraulic head as "
       "time:value pairs, linear in between, the last value held after the last time (dp = -rho_w g h); "
       "positive is a drop"),
    _s("pfault_material_<material>_pressure_change", "table", None, "Pa", "pore-pressure change as "
       "time:value pairs, linear in between, the last value held after the last time; negative is a "
       "drawdown"),
    _s("pfault_material_<material>_hydraulic_conductivity", "property", None, "m/s", "isotropic hydraulic "
       "conductivity K (required with -pfault_flow)"),
    _s("pfault_material_<material>_specific_storage", "property", None, "1/m", "specific storage S_s (default: "
       "rho_w g (alpha c_M + n beta_w), c_M oedometric compressibility, n = e/(1+e), beta_w = 4.4e-10 1/Pa)"),
    _s("pfault_material_<material>_void_ratio", "property", 0.7, "", "void ratio e (porosity e/(1+e) in the "
       "specific storage); the initial void ratio e0 of the compression-index law, which needs it given"),
    # boundary conditions
    _s("pfault_bc_<surface>_type", "choice", "free", "", "boundary condition on a physical surface",
       choices=("free", "fixed", "roller", "traction", "displacement")),
    _s("pfault_bc_<surface>_traction", "list", "0,0,0", "Pa", "traction vector tx,ty,tz (types traction and "
       "displacement; on the latter it acts on the components left free)"),
    _s("pfault_bc_<surface>_displacement", "list", "0,0,0", "m", "prescribed displacement ux,uy,uz for type "
       "displacement"),
    _s("pfault_bc_<surface>_components", "names", "x,y,z", "", "components prescribed by type displacement"),
    _s("pfault_bc_<surface>_history", "table", None, "", "time:scale table multiplying the surface's "
       "traction and displacement, the last value held after the last time (default: constant 1)"),
    # faults
    _s("pfault_faults", "names", "", "", "physical surfaces that are faults (split, with contact and friction)"),
    _s("pfault_fault_<fault>_cohesion", "quantity", 0.0, "Pa", "cohesion c of the Mohr-Coulomb criterion (a "
       "face opens at the cone's apex, a tensile effective normal traction c / tan(phi), unless "
       "-pfault_fault_<fault>_tension_cutoff zero)"),
    _s("pfault_fault_<fault>_friction_angle", "quantity", 30.0, "degree", "friction angle phi"),
    _s("pfault_fault_<fault>_tensile_strength", "quantity", 0.0, "Pa", "tensile strength T of the intact surface: "
       "with T > 0 the fault is a candidate surface whose faces stay glued until the effective normal traction "
       "exceeds min(T, c / tan(phi)) or the shear c - t_N tan(phi), then break for good (0: a pre-existing "
       "fault, every face broken from the start)"),
    _s("pfault_fault_<fault>_tension_cutoff", "choice", "apex", "", "where the fault's law opens: apex, at the "
       "Mohr-Coulomb cone's apex, a tensile effective normal traction c / tan(phi) (the shear strength falls to zero "
       "as the face opens); zero, at t_N = 0 (a fault that carries no tension: a cohesive face opens as soon as its "
       "effective normal traction is tensile, its shear strength dropping from c to 0, which Newton converges on "
       "less easily). A candidate surface's intact faces keep min(T, c / tan(phi)); this sets the law of its "
       "broken faces (cohesion c_r)", choices=("apex", "zero")),
    _s("pfault_fault_<fault>_residual_cohesion", "quantity", 0.0, "Pa", "cohesion of a broken face of a "
       "candidate surface (at most the cohesion; a broken face opens at c_r / tan(phi), or at zero with "
       "-pfault_fault_<fault>_tension_cutoff zero)"),
    _s("pfault_fault_<fault>_method", "choice", "lagrange", "", "contact enforcement",
       choices=("lagrange", "penalty")),
    _s("pfault_fault_<fault>_penalty_normal", "quantity", 0.0, "Pa/m", "normal penalty stiffness (0: E/h of "
       "the adjacent cell)"),
    _s("pfault_fault_<fault>_penalty_tangential", "quantity", 0.0, "Pa/m", "tangential penalty stiffness "
       "(0: E/h of the adjacent cell)"),
    _s("pfault_contact_effective_stress", "bool", True, "", "friction and opening act on the effective normal "
       "traction t_N + alpha p (Terzaghi; p the pore pressure at the face: hydrostatic below the water table "
       "in a geostatic scene, plus the change); an open face carries the water pressure. false: on the total "
       "traction (dry faults)"),
    _s("pfault_contact_suction", "bool", False, "", "effective-stress law in a geostatic scene: false (default) "
       "clamps the fault's pore pressure at zero, so a face above the lowered water table is dry (neither water "
       "pressure nor suction acts on it); true keeps the negative pressure, whose suction then presses the "
       "faces together"),
    _s("pfault_contact_monitor", "bool", False, "", "print one line per Newton iteration of fault scenes: "
       "residual norm, stick/slip/open counts and how many faces changed state"),
    # solver
    _s("pfault_solver", "string", "auto", "", "solver options file: auto (mumps below 50,000 unknowns or where "
       "faults need it, iterative above), a path, solver/NAME.opts beside the scene, or one of pfault's (mumps, gamg, "
       "iterative); its options apply where not set by the scene or the command line"),
    # loading / initial state
    _s("pfault_geostatic", "bool", False, "", "start from a geostatic stress state (gravity, K0)"),
    _s("pfault_geostatic_stress", "choice", "gravity", "", "the initial vertical stress of a geostatic start: "
       "gravity, the elastic gravity solve with the faults glued (the overburden in flat layers, the arching around "
       "stiff bodies and the sediment hung on a stiff rock beside a fault); lithostatic, the weight of the column "
       "above each cell's centroid, sigma_v = -int rho g dz up to the land surface (flat layers' stress whatever the "
       "geometry, not in equilibrium where the layers are not flat; no gravity solve). Horizontal stresses by the "
       "K0 rule either way", choices=("gravity", "lithostatic")),
    _s("pfault_geostatic_k0", "quantity", None, "", "ratio K0 >= 0 of horizontal to vertical effective stress "
       "(hydrostatic pore pressure below -pfault_water_table); unset: nu/(1-nu) of each material"),
    _s("pfault_gravity", "quantity", 9.80665, "m/s**2", "gravitational acceleration"),
    _s("pfault_water_density", "quantity", 1000.0, "kg/m**3", "density of water (head to pressure)"),
    _s("pfault_water_table", "quantity", 0.0, "m", "elevation of the initial water table (hydrostatic "
       "initial pore pressure below it)"),
    _s("pfault_pore_pressure_unchanged_materials", "names", "", "", "materials whose pore pressure does not change, "
       "whatever the pore-pressure source (per-material tables, -pfault_flow, -pfault_heads_file) gives there: an "
       "impermeable rock, a clay the wells do not drain. Their cells take no pore-pressure change (no Biot load, zero "
       "in fields.h5's pore_pressure_change), nor do the fault faces whose minus side they are; a flow model still "
       "solves for the head in them (default: none)"),
    # groundwater flow
    _s("pfault_flow", "bool", False, "", "solve transient groundwater flow for the head change and load the "
       "skeleton with dp = rho_w g h (instead of per-material tables)"),
    _s("pfault_flow_wells", "list", "", "m", "well positions x1,y1,x2,y2,..."),
    _s("pfault_flow_well_screen", "list", "", "m", "z_top,z_bottom of the screen of every well"),
    _s("pfault_flow_well_rate", "table", None, "m**3/s", "pumping rate per well as time:rate pairs, linear in "
       "between (units allowed, e.g. 0:0,1*year:300*L/s); positive is extraction"),
    _s("pfault_flow_fixed_head_surfaces", "names", "", "", "physical surfaces held at h = 0 (others are "
       "no-flow)"),
    _s("pfault_flow_substeps", "int", 1, "", "backward-Euler flow steps per mechanical time step"),
    # pore pressure from a site's groundwater model
    _s("pfault_heads_file", "string", "", "", "heads saved by the site's groundwater model: a MODFLOW 6 binary "
       "head file (with -pfault_heads_grid), or heads / pressure changes at times on a regular grid or on points in "
       "HDF5 or NetCDF-4 (.h5, .nc; layout in README); each cell takes the value at its centroid, linear in time "
       "between saved times, dp = rho_w g (h - h_ref) (instead of per-material tables or -pfault_flow)"),
    _s("pfault_heads_grid", "string", "", "", "binary grid file of the MODFLOW 6 model that wrote "
       "-pfault_heads_file (MODEL.dis.grb or MODEL.disv.grb): cells, layer elevations, IDOMAIN, XORIGIN, YORIGIN, "
       "ANGROT"),
    _s("pfault_heads_time_unit", "string", "day", "", "unit of the times in -pfault_heads_file (MODFLOW's "
       "TIME_UNITS: s, minute, hour, day, year, or a number of seconds); the time 0 of the file is pfault's; an "
       "HDF5/NetCDF file's time units attribute is used when present"),
    _s("pfault_heads_length_unit", "quantity", 1.0, "m", "length unit of the MODFLOW model (its grid and heads): "
       "1 for metres, 0.3048 for feet"),
    _s("pfault_heads_reference_time", "quantity", None, "s", "saved time of -pfault_heads_file whose heads are "
       "h_ref, the state pfault's initial state stands for (default: the first saved time, with a warning when it is "
       "after the run's time 0: give this option to say those heads are the state at rest)"),
    _s("pfault_heads_outside", "choice", "error", "", "mesh cells whose centroid is outside the groundwater model "
       "(beyond its extent, above its top, below its bottom, or in an inactive cell): error, or zero (no "
       "pore-pressure change there; the run says how many cells and what share of the volume, and stops if that is "
       "every cell)", choices=("error", "zero")),
    _s("pfault_mesh_origin", "list", "0,0,0", "m", "site coordinates of the mesh's origin: site = mesh + origin "
       "(the coordinates of the groundwater model and of other site data)"),
    _s("pfault_crs", "string", "", "", "coordinate reference system of the site coordinates: an EPSG code "
       "(EPSG:32650), a .prj/.wkt file or a WKT string; a projected CRS in metres. With it every raster is also a "
       "GeoTIFF, the CF NetCDF files carry it, and gis/ holds the fault, fissure and hazard layers and the stations "
       "as east/north/up series; heads in another CRS are reprojected"),
    _s("pfault_start_date", "string", "", "", "calendar date of the scene's time 0, ISO 8601 (2015-01-01, "
       "2015-01-01T06:00:00; UTC): outputs give dates, and InSAR dates are placed in the run"),
    # time
    _s("pfault_time_end", "quantity", 1.0, "s", "end time (units allowed, e.g. 10*year)"),
    _s("pfault_time_steps", "int", 1, "", "number of equal time steps"),
    _s("pfault_time_max_cuts", "int", 3, "", "a fault step whose Newton solve does not converge is retried as "
       "2, 4, ... equal sub-steps, halving up to this many times (0: no retry); the pore pressure of a flow "
       "model is interpolated linearly in time between its steps"),
    # output: restart and figures
    _s("pfault_restart", "string", "", "", "run directory to continue from its last completed step (its "
       "checkpoint.h5), up to -pfault_time_end; the checkpoint's time must be a point of the time grid "
       "-pfault_time_end and -pfault_time_steps give; writes into that directory unless -pfault_output_dir "
       "is given"),
    _s("pfault_restart_changed_inputs", "names", "", "", "with -pfault_restart: options whose data files may differ "
       "from those the continued run read (its checkpoint.h5 records each file's size and SHA-256), e.g. "
       "pfault_heads_file for a head file a longer model run extended: the continued steps read the files as they "
       "are now, the steps up to the checkpoint stay those of the old files, and summary.json lists them "
       "(restart.changed_inputs); without it a changed data file is an error"),
    # output: observations
    _s("pfault_stations", "string", "", "", "CSV file of stations, header name,x,y,z[,side] (site coordinates, m; "
       "side plus|minus: the side a station on a fault takes, default minus): their displacement at time 0 and after "
       "every step in station_displacement.csv and .h5"),
    _s("pfault_insar_los", "list", "", "", "unit vector e,n,u from the ground to the satellite (u > 0; e.g. "
       "-0.61,-0.11,0.785 for Sentinel-1 ascending): the land surface's "
       "line-of-sight displacement (positive towards the satellite) and its rate at every output time on a raster, "
       "insar_los.nc (CF NetCDF) and insar_los.png"),
    _s("pfault_insar_spacing", "quantity", None, "m", "pixel size of the LOS raster (default: the mean edge length "
       "of the land surface's triangles; not used with -pfault_insar_grid); a raster that would not fit in memory is "
       "refused"),
    _s("pfault_insar_grid", "string", "", "", "InSAR product (OPERA DISP-S1 or MintPy layout, NetCDF/HDF5) whose "
       "pixels the LOS raster takes instead of a regular grid: its pixel centres in its CRS, and its per-pixel "
       "line of sight when it has one (los_east, los_north), else -pfault_insar_los"),
    _s("pfault_map_spacing", "quantity", None, "m", "pixel size of the land surface's maps in gis/ (subsidence, "
       "horizontal strain, angular distortion; default: -pfault_insar_spacing when given, else the mean edge length "
       "of the land surface's triangles)"),
    _s("pfault_gis", "bool", True, "", "with -pfault_crs, write the GIS layers (gis/: GeoTIFFs, GeoPackage, "
       "stations' east/north/up series) at the end of the run"),
    _s("pfault_hazard_strain_threshold", "quantity", 2e-4, "", "horizontal tensile strain of the land surface "
       "above which it is fissure-prone (2e-4: within the 1e-4 to 7e-4 measured across active earth fissures): "
       "summary.json's fissure-prone length and area"),
    _s("pfault_figures", "choice", "apart", "", "PNG figures next to the output at the end of the run (fault "
       "opening and slip, subsidence map, histories of the maxima, earth-fissure hazard map): apart, drawn by a "
       "process of their own that the run starts once its summary.json is written and does not wait for (a few "
       "seconds later; its messages in figures.log); true, drawn by the run before it ends; false, none",
       choices=("apart", "true", "false")),
    _s("pfault_margins", "bool", True, "", "margins to failure at every output time: the further uniform drawdown "
       "(m of head) of the loaded materials at which each fault face would slip, open or break, from the linear "
       "response of the converged state (fault.h5 margin_*, summary.json faults/NAME/margin, fault_margins.png)"),
    _s("pfault_margin_thresholds", "list", "1,5,10", "m", "drawdowns (m of head) for which summary.json gives each "
       "fault's area whose margin is within them"),
]

_PLACEHOLDERS = ("<material>", "<surface>", "<fault>")


def spec_for(name: str) -> Spec | None:
    """The Spec of a concrete option name (patterns matched by prefix and suffix)."""
    for s in SPECS:
        if s.name == name:
            return s
    for s in SPECS:
        for ph in _PLACEHOLDERS:
            if ph in s.name:
                head, tail = s.name.split(ph)
                if name.startswith(head) and name.endswith(tail) and len(name) > len(head) + len(tail):
                    return s
    return None


def help_text() -> str:
    lines = ["pfault options (units in brackets; quantities accept units such as 10*year, -0.1*MPa; a material "
             "property may name a spatial field instead, field:FILE[,variable=NAME][,outside=nearest], CSV, HDF5 "
             "or NetCDF points or grid in x, y, z, interpolated at the cell centroids):", ""]
    width = max(len(s.name) for s in SPECS) + 2
    for s in SPECS:
        default = "" if s.default in (None, "") else f" (default {s.default})"
        if s.default is None:
            default = " (required)" if "required" in s.help else ""
        unit = f" [{s.unit}]" if s.unit else ""
        choices = f" {{{'|'.join(s.choices)}}}" if s.choices else ""
        lines.append(f"  -{s.name:<{width}}{s.help}{choices}{unit}{default}")
    lines.append("")
    lines.append("Solver options are PETSc's (-snes_*, -ksp_*, -pc_*, -fieldsplit_displacement_*). "
                 "Any option may be set in the scene file or on the command line; the command line wins.")
    lines += ["", exit_code_table()]
    return "\n".join(lines)


class OptionReader:
    """Reads typed -pfault_ options and remembers which ones were asked for."""

    def __init__(self, PETSc: ModuleType) -> None:
        self.PETSc = PETSc
        self.db = PETSc.Options()
        self.queried: set[str] = set()
        self.resolved: dict[str, object] = {}

    def has(self, name: str) -> bool:
        self.queried.add(name)
        return self.db.hasName(name)

    def raw(self, name: str) -> str | None:
        self.queried.add(name)
        if not self.db.hasName(name):
            return None
        return self.db.getString(name)

    def get(self, name: str, default: Any = ..., kind: str | None = None) -> Any:
        spec = spec_for(name)
        if spec is None:
            raise RuntimeError(f"option -{name} is not declared in pfault.options.SPECS")
        kind = kind or spec.kind
        if default is ...:
            default = spec.default
        text = self.raw(name)
        if text is None:
            value = self._convert(spec, kind, default, name) if isinstance(default, str) and kind not in (
                "string", "choice") else default
        else:
            value = self._convert(spec, kind, text, name)
        self.resolved[name] = value
        return value

    def _convert(self, spec, kind, text, name):
        if kind in ("string",):
            return str(text)
        if kind == "choice":
            if text not in spec.choices:
                raise InputError(f"-{name}: '{text}' is not one of {', '.join(spec.choices)}")
            return text
        if kind == "bool":
            t = str(text).strip().lower()
            if t in ("", "1", "true", "yes", "on"):
                return True
            if t in ("0", "false", "no", "off"):
                return False
            raise InputError(f"-{name}: '{text}' is not true or false")
        if kind == "int":
            return _whole_number(text, name)
        if kind == "ints":
            return [_whole_number(t, name) for t in str(text).split(",") if t.strip()]
        if kind in ("real", "quantity"):
            return parse_quantity(text, name, spec.unit)
        if kind == "property":
            # a number, or field:FILE[,variable=NAME][,outside=error|nearest] (pfault.materials.properties)
            if str(text).strip().startswith(FIELD_PREFIX):
                return parse_field(str(text), name, spec.unit)
            return parse_quantity(text, name, spec.unit)
        if kind == "list":
            return parse_list(text, name, spec.unit) if str(text).strip() else []
        if kind == "table":
            return parse_table(text, name, spec.unit)
        if kind == "names":
            return [s.strip() for s in str(text).split(",") if s.strip()]
        raise RuntimeError(kind)

    def unknown_pfault_options(self) -> list[str]:
        """-pfault_ options in the database that nothing asked for (typos, or names not in the mesh)."""
        names = [k for k in self.db.getAll() if k.startswith("pfault_")]
        return sorted(n for n in names if n not in self.queried)

    def check_pfault_options(self) -> None:
        unknown = self.unknown_pfault_options()
        if unknown:
            raise InputError(_unknown_message(unknown[0], self.queried | {s.name for s in SPECS}))


def _whole_number(text, name):
    try:
        return int(str(text))
    except ValueError:
        raise InputError(f"-{name}: '{text}' is not a whole number") from None


def _unknown_message(name, candidates):
    close = difflib.get_close_matches(name, sorted(candidates), n=1, cutoff=0.6)
    hint = f"; did you mean -{close[0]}?" if close else "; see python -m pfault -help"
    spec = spec_for(name)
    if spec is not None:
        hint = (f"; the name in it does not match any physical volume/surface or fault of the mesh, "
                f"or the option does not apply to this scene")
    return f"unused option -{name}{hint}"


# options PETSc reads only at finalize or that are not recorded as used but are legitimate
_PETSC_LATE_OPTIONS = {"log_view", "options_left", "help", "options_file", "log_view_memory", "log_trace",
                       "malloc_dump", "malloc_debug", "memory_view", "objects_dump", "info", "log_all",
                       "on_error_abort", "on_error_attach_debugger", "start_in_debugger", "nox",
                       "check_pointer_intensity", "error_output_stdout", "options_view"}


def unused_petsc_options(PETSc: ModuleType) -> list[str]:
    """Names of options in the PETSc database that no object has read (as -options_left reports)."""
    return sorted(x for x in options_left(PETSc) if x not in _PETSC_LATE_OPTIONS and not x.startswith("pfault_"))


def check_unused_petsc_options(PETSc: ModuleType, reader: OptionReader) -> None:
    """InputError on every rank if any rank has an option that no PETSc object read: what each rank has
    read can differ (objects made on some ranks only, such as per-rank sub-solvers), and an error raised
    on one rank only would leave the others waiting."""
    left = unused_petsc_options(PETSc)
    message = None
    if left:
        message = (f"unused option -{left[0]}: no PETSc object in this run reads it (misspelled, or it does not "
                   "apply to the chosen solver); remove it or fix its name")
    collective_check(PETSc.COMM_WORLD, message)
