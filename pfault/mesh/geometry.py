"""Built-in gmsh meshes of the two case studies of Franceschini et al. (Proc. IAHS 372, 63-68, 2015).

Coordinates: z up, land surface at z = 0, metres. Each builder returns a :class:`SerialMesh` whose physical
volumes are the materials (``sand``, ``clay``, ``rock``) and whose named surfaces are the six outer
boundary planes ``xmin xmax ymin ymax bottom top`` plus the rupture surface (``fissure`` at Wuxi, ``fault``
at Queretaro). The rupture surface is conforming: the geometry is cut along it with an OCC boolean
fragment, so each of its triangles is a face shared by exactly two tetrahedra (one on either side).

``size_factor`` multiplies every element size (lateral and vertical): 2 gives about 8x fewer tetrahedra
at Queretaro and about 4x fewer at Wuxi, whose thin layers already bound the element height away from
the ridge. At ``size_factor=1`` both meshes land within 10 % of the node, tetrahedron and fault-triangle
counts of the paper (see benchmarks/mesh_sizes.py).

Meshing is deterministic: one thread, fixed random seed, fixed algorithms. gmsh prints nothing; if the
caller has already initialized gmsh, the builder works in a model of its own, restores the options it
changed and leaves gmsh initialized.
"""

from __future__ import annotations

import contextlib
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from .gmsh_io import from_gmsh_model
from .serial import SerialMesh

# ------------------------------------------------------------------------------------------------------
# Wuxi (Su-Xi-Chang, Jiangsu, China): earth fissure above a buried bedrock ridge
# ------------------------------------------------------------------------------------------------------
WUXI_SIZE = (2000.0, 5000.0, 250.0)           # Lx, Ly, depth (m)
WUXI_DEFAULTS: dict[str, Any] = dict(
    ridge_x=1000.0,                  # x of the ridge crest line and of the fissure plane (m)
    crest_depth=5.0,                 # depth of the bedrock crest below the land surface (m)
    bedrock_depth=100.0,             # depth of the bedrock top away from the ridge (m)
    ridge_half_width=100.0,          # horizontal distance from the crest to the foot of each flank (m)
    interfaces=(20.0, 50.0, 80.0),   # depths of the clay/sand interfaces above the bedrock (m)
)
# element sizes at size_factor 1: on the fissure and the crest line (m; 938 segments along y, i.e. 1876
# fissure triangles as in the paper), growth per metre of distance from them, largest size (m)
_WUXI_H_FISSURE = 5000.0 / 938.0
_WUXI_GROWTH = 0.42
_WUXI_H_MAX = 95.0

# ------------------------------------------------------------------------------------------------------
# Queretaro (Mexico): pre-existing fault between outcropping rock and the sedimentary aquifer
# ------------------------------------------------------------------------------------------------------
QUERETARO_SIZE = (30000.0, 30000.0, 50.0)     # Lx, Ly, depth (m)
QUERETARO_WELLS = ((12000.0, 12000.0), (12000.0, 15000.0), (12000.0, 18000.0))
QUERETARO_DEFAULTS: dict[str, Any] = dict(
    fault_x=10000.0,                 # x of the vertical fault plane; rock for x < fault_x (m)
    clay_thickness=20.0,             # clay aquitard 0..20 m over the sand aquifer 20..50 m (m)
    wells=QUERETARO_WELLS,           # (x, y) of the pumping wells (m); refinement only
    fault_size=52.0,                 # element size along and across the fault at size_factor 1 (m)
    surface_size=None,               # element height at the land surface at size_factor 1 (m); None: layers
    layer_thickness=50.0 / 7.0,      # layer thickness of the extrusion at size_factor 1 (m; 7 layers over 50 m)
)
_QRO_GROWTH = 0.25
_QRO_H_WELL = 40.0
_QRO_H_MAX = 1000.0
_QRO_DZ_GROWTH = 0.5                 # growth of the layer height with depth under surface_size (m per m)


# ------------------------------------------------------------------------------------------------------
# gmsh session handling
# ------------------------------------------------------------------------------------------------------
_OPTIONS = {
    "General.Terminal": 0,
    "General.Verbosity": 1,
    "General.NumThreads": 1,
    "Mesh.MaxNumThreads1D": 1,
    "Mesh.MaxNumThreads2D": 1,
    "Mesh.MaxNumThreads3D": 1,
    "Mesh.RandomSeed": 1,
    "Mesh.ElementOrder": 1,
    "Mesh.Algorithm": 6,             # Frontal-Delaunay triangles
    "Mesh.Algorithm3D": 1,           # Delaunay tetrahedra
    "Mesh.Optimize": 1,
    "Mesh.OptimizeNetgen": 0,
    "Mesh.RecombineAll": 0,
    "Mesh.MeshSizeFromPoints": 0,
    "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeExtendFromBoundary": 0,
    "Mesh.MeshSizeMin": 0.0,
    "Mesh.MeshSizeMax": 1e22,
    "Mesh.MeshSizeFactor": 1.0,
    "Geometry.OCCBooleanPreserveNumbering": 1,
}


@contextlib.contextmanager
def _gmsh_model(name):
    """A fresh gmsh model with pfault's meshing options; restores the caller's gmsh state afterwards."""
    import gmsh
    initialized = gmsh.isInitialized()
    if not initialized:
        gmsh.initialize(["pfault"], readConfigFiles=False)
    saved = {}
    previous = None
    try:
        for key, value in _OPTIONS.items():
            saved[key] = gmsh.option.getNumber(key)
            gmsh.option.setNumber(key, value)
        if initialized:
            previous = gmsh.model.getCurrent()
        gmsh.model.add(name)
        yield gmsh
    finally:
        if initialized:
            with contextlib.suppress(Exception):
                gmsh.model.setCurrent(name)
                gmsh.model.remove()
            if previous is not None:
                with contextlib.suppress(Exception):
                    gmsh.model.setCurrent(previous)
            for key, value in saved.items():
                gmsh.option.setNumber(key, value)
        else:
            gmsh.finalize()


def _check_factor(size_factor):
    try:
        f = float(size_factor)
    except (TypeError, ValueError):
        raise InputError(f"-pfault_mesh_size_factor: '{size_factor}' is not a number") from None
    if not (math.isfinite(f) and 0.25 <= f <= 20.0):
        raise InputError(f"-pfault_mesh_size_factor: must lie in [0.25, 20], got {size_factor}")
    return f


def _real(value, option):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"-{option}: '{value}' is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"-{option}: must be finite, got {value}")
    return v


def _unknown(params, defaults, prefix):
    extra = sorted(set(params) - set(defaults))
    if extra:
        raise InputError(f"-{prefix}{extra[0]}: unknown parameter of this mesh (known: {', '.join(sorted(defaults))})")


def _polygon(occ, points, y=0.0):
    """Plane surface in the x-z plane (at y) bounded by the closed polygon ``points`` [(x, z), ...]."""
    tags = [occ.addPoint(x, y, z) for x, z in points]
    lines = [occ.addLine(tags[i], tags[(i + 1) % len(tags)]) for i in range(len(tags))]
    return occ.addPlaneSurface([occ.addCurveLoop(lines)])


def _outer_surfaces(gmsh, bounds, tol):
    """Group the boundary surfaces of the model by the outer plane they lie on."""
    x0, y0, z0, x1, y1, z1 = bounds
    groups = {name: [] for name in ("xmin", "xmax", "ymin", "ymax", "bottom", "top")}
    planes = (("xmin", 0, x0), ("xmax", 0, x1), ("ymin", 1, y0), ("ymax", 1, y1), ("bottom", 2, z0), ("top", 2, z1))
    for _, tag in gmsh.model.getEntities(2):
        bb = gmsh.model.getBoundingBox(2, tag)
        for name, axis, value in planes:
            if abs(bb[axis] - value) < tol and abs(bb[axis + 3] - value) < tol:
                groups[name].append(tag)
    return groups


def _physical(gmsh, dim, tags, name):
    tag = gmsh.model.addPhysicalGroup(dim, sorted(tags))
    gmsh.model.setPhysicalName(dim, tag, name)


def _x_plane_surfaces(gmsh, x, tol, z_min=-math.inf):
    """The model's surfaces in the plane x (above z_min)."""
    found = []
    for _, tag in gmsh.model.getEntities(2):
        bb = gmsh.model.getBoundingBox(2, tag)
        if abs(bb[0] - x) < tol and abs(bb[3] - x) < tol and bb[2] > z_min:
            found.append(tag)
    return found


def _physical_surfaces(gmsh, groups, mesh_name):
    """A physical surface per group {name: surface tags}, none of them empty."""
    for name, tags in groups.items():
        if not tags:
            raise RuntimeError(f"{mesh_name}: no surface found for '{name}'")
        _physical(gmsh, 2, tags, name)


def _size_field(gmsh, expr):
    """The element size everywhere: the MathEval expression ``expr`` of x, y, z (m)."""
    field = gmsh.model.mesh.field.add("MathEval")
    gmsh.model.mesh.field.setString(field, "F", expr)
    gmsh.model.mesh.field.setAsBackgroundMesh(field)


# ------------------------------------------------------------------------------------------------------
# Wuxi
# ------------------------------------------------------------------------------------------------------
def wuxi_bedrock_top(x: ArrayLike, ridge_x: float = WUXI_DEFAULTS["ridge_x"],
                     crest_depth: float = WUXI_DEFAULTS["crest_depth"],
                     bedrock_depth: float = WUXI_DEFAULTS["bedrock_depth"],
                     ridge_half_width: float = WUXI_DEFAULTS["ridge_half_width"]) -> np.ndarray:
    """Elevation z (m, negative) of the bedrock top at x: the piecewise-linear ridge profile."""
    x = np.asarray(x, dtype=float)
    slope = (bedrock_depth - crest_depth) / ridge_half_width
    return np.maximum(-bedrock_depth, -crest_depth - slope * np.abs(x - ridge_x))


def _wuxi_params(params):
    _unknown(params, WUXI_DEFAULTS, "pfault_wuxi_")
    p = dict(WUXI_DEFAULTS)
    p.update({k: v for k, v in params.items() if v is not None})
    for key in ("ridge_x", "crest_depth", "bedrock_depth", "ridge_half_width"):
        p[key] = _real(p[key], f"pfault_wuxi_{key}")
    try:
        p["interfaces"] = tuple(_real(d, "pfault_wuxi_interfaces") for d in p["interfaces"])
    except TypeError:
        raise InputError("-pfault_wuxi_interfaces: give the interface depths as a list d1,d2,... (m)") from None
    lx, _, depth = WUXI_SIZE
    c, d, w, xr = p["crest_depth"], p["bedrock_depth"], p["ridge_half_width"], p["ridge_x"]
    if not 0.0 < c:
        raise InputError(f"-pfault_wuxi_crest_depth: must be positive (the fissure spans the ground down to "
                         f"the crest), got {c}")
    if not c < d < depth - 10.0:
        raise InputError(f"-pfault_wuxi_bedrock_depth: must lie between the crest depth {c:g} m and "
                         f"{depth - 10.0:g} m, got {d}")
    if not w > 0.0:
        raise InputError(f"-pfault_wuxi_ridge_half_width: must be positive, got {w}")
    if not (xr - w > 0.0 and xr + w < lx):
        raise InputError(f"-pfault_wuxi_ridge_x: the ridge {xr:g} +- {w:g} m must lie inside 0 < x < {lx:g} m "
                         "(or reduce -pfault_wuxi_ridge_half_width)")
    depths = p["interfaces"]
    if len(depths) > 5:
        raise InputError("-pfault_wuxi_interfaces: at most 5 interfaces (6 layers)")
    if any(not a < b for a, b in zip((0.0,) + depths, depths + (d,))):
        raise InputError(f"-pfault_wuxi_interfaces: depths must increase strictly between 0 and the bedrock "
                         f"depth {d:g} m, got {','.join(f'{v:g}' for v in depths)}")
    if any(abs(v - c) < 0.5 for v in depths):
        raise InputError(f"-pfault_wuxi_interfaces: keep the interfaces at least 0.5 m from the crest depth "
                         f"{c:g} m")
    return p


def wuxi_mesh(size_factor: float = 1.0, **params: Any) -> SerialMesh:
    """Earth fissure above a buried bedrock ridge (Wuxi, Su-Xi-Chang area, China).

    Domain 0 <= x <= 2000 m, 0 <= y <= 5000 m, -250 <= z <= 0. The geometry does not vary along y.

    Bedrock (material ``rock``): its top follows the piecewise-linear profile of
    :func:`wuxi_bedrock_top`: a crest at ``crest_depth`` (5 m) below the surface along the line
    x = ``ridge_x`` (1000 m), flanks dipping linearly to ``bedrock_depth`` (100 m) at a horizontal
    distance ``ridge_half_width`` (100 m, a dip of about 43 degrees), flat beyond. This schematises the
    buried bedrock highs under the Quaternary cover of the Su-Xi-Chang plain: their shallowest points
    sit a few metres below ground, and the fissures open above them, where the compressible cover is
    thinnest and its thickness changes fastest. Planar flanks keep the geometry exact and easy to mesh.
    The paper does not give its profile; the fissure's opening grows with the flank dip (about 5 cm for
    500 m, 11 degrees, and 14 cm for the default 100 m, of the paper's ~0.2 m).

    Quaternary cover: horizontal layers, alternately clay (aquitards, material ``clay``) and sand
    (aquifers, material ``sand``) from the top, separated at the depths ``interfaces`` (default 20, 50,
    80 m; chosen for this reproduction as a plausible Su-Xi-Chang sequence, at most four layers):

    ========  =========  ===========================================================
    depth m   material   role (Su-Xi-Chang multi-aquifer system)
    ========  =========  ===========================================================
    0-20      clay       surficial aquitard (holds the phreatic water)
    20-50     sand       first confined aquifer
    50-80     clay       aquitard
    80-100    sand       second confined aquifer, the main exploited one, on bedrock
    ========  =========  ===========================================================

    Each layer is truncated by the bedrock: over the ridge the deeper layers pinch out on the flanks and
    only the top clay (``crest_depth`` thick) covers the crest.

    Fissure (named surface ``fissure``): the vertical plane x = ``ridge_x`` over the whole y length, from
    the land surface down to the bedrock crest (its bottom edge is the crest line on the rock). It splits
    the top clay into two volumes sharing it.

    Element sizes (times ``size_factor``): 5.33 m on the fissure and along the crest line, growing by
    0.42 m per metre of distance from them, at most 95 m. The fissure itself is a structured strip of
    938 segments along y and one row down to the crest (1876 triangles, as in the paper; more rows
    when size_factor < 1 makes them taller than wide). The 20-30 m layers bound the element height
    far from the ridge, so a size_factor of 2 gives only about 4x fewer tetrahedra here.
    """
    f = _check_factor(size_factor)
    p = _wuxi_params(params)
    with _gmsh_model("pfault_wuxi") as gmsh:
        _wuxi_volumes(gmsh.model.occ, p)
        fissure = _wuxi_groups(gmsh, p)
        _wuxi_sizes(gmsh, fissure, p, f)
        gmsh.model.mesh.generate(3)
        return from_gmsh_model(source="wuxi")


def _wuxi_volumes(occ, p):
    """The volumes: the cross-section in the x-z plane (y = 0), the bedrock polygon and the layer strips minus
    the bedrock, cut by the fissure's trace, extruded along y and glued (faces shared by two volumes become
    one)."""
    lx, ly, depth = WUXI_SIZE
    xr, c, d, w = p["ridge_x"], p["crest_depth"], p["bedrock_depth"], p["ridge_half_width"]
    rock = _polygon(occ, [(0.0, -depth), (lx, -depth), (lx, -d), (xr + w, -d), (xr, -c), (xr - w, -d),
                          (0.0, -d)])
    tops = (0.0,) + p["interfaces"]
    bottoms = p["interfaces"] + (depth,)
    faces = [(2, rock)]
    for top, bottom in zip(tops, bottoms):
        strip = _polygon(occ, [(0.0, -bottom), (lx, -bottom), (lx, -top), (0.0, -top)])
        out, _ = occ.cut([(2, strip)], [(2, rock)], removeObject=True, removeTool=False)
        faces += out
    trace = occ.addLine(occ.addPoint(xr, 0.0, 0.0), occ.addPoint(xr, 0.0, -c))
    faces, _ = occ.fragment(faces, [(1, trace)])
    faces = [dt for dt in faces if dt[0] == 2]
    out = occ.extrude(faces, 0.0, ly, 0.0)
    vols = [dt for dt in out if dt[0] == 3]
    occ.fragment(vols[:1], vols[1:])       # glue: faces shared by two volumes become one
    occ.synchronize()


def _wuxi_groups(gmsh, p):
    """Physical volumes (rock under the bedrock top, clay and sand layers above) and surfaces (the six sides, the
    fissure); returns the fissure's surface tags."""
    occ = gmsh.model.occ
    lx, ly, depth = WUXI_SIZE
    xr, c, d, w = p["ridge_x"], p["crest_depth"], p["bedrock_depth"], p["ridge_half_width"]
    tol = 1e-6 * ly
    bottoms = p["interfaces"] + (depth,)
    materials = {"clay": [], "sand": [], "rock": []}
    layer_names = ["clay" if i % 2 == 0 else "sand" for i in range(len(bottoms))]
    for _, tag in gmsh.model.getEntities(3):
        x, _, z = occ.getCenterOfMass(3, tag)
        zb = wuxi_bedrock_top(x, xr, c, d, w)
        if z < zb:
            materials["rock"].append(tag)
        else:
            materials[layer_names[int(np.searchsorted(bottoms, -z))]].append(tag)
    for name, tags in materials.items():
        if tags:
            _physical(gmsh, 3, tags, name)
    groups = _outer_surfaces(gmsh, (0.0, 0.0, -depth, lx, ly, 0.0), tol)
    groups["fissure"] = fissure = _x_plane_surfaces(gmsh, xr, tol, z_min=-c - tol)
    _physical_surfaces(gmsh, groups, "wuxi_mesh")
    return fissure


def _wuxi_sizes(gmsh, fissure, p, f):
    """Element sizes: the fissure a structured strip of segments of h along y (1876 triangles at size_factor 1,
    as in the paper) with as few rows down to the crest as keep the triangles near isotropic; elsewhere a size
    growing with the distance (in the x-z plane) from the fissure segment, whose bottom end is the crest line."""
    h = _WUXI_H_FISSURE * f
    for tag in fissure:
        for _, curve in gmsh.model.getBoundary([(2, tag)], oriented=False):
            bb = gmsh.model.getBoundingBox(1, curve)
            length = max(bb[4] - bb[1], bb[5] - bb[2])
            gmsh.model.mesh.setTransfiniteCurve(curve, max(1, int(round(length / h))) + 1)
        gmsh.model.mesh.setTransfiniteSurface(tag)
    xr, c = p["ridge_x"], p["crest_depth"]
    dist = f"Sqrt((x-{xr!r})*(x-{xr!r}) + Max(0,{-c!r}-z)*Max(0,{-c!r}-z))"
    _size_field(gmsh, f"{f!r}*Min({_WUXI_H_MAX!r}, {_WUXI_H_FISSURE!r} + {_WUXI_GROWTH!r}*{dist})")


# ------------------------------------------------------------------------------------------------------
# Queretaro
# ------------------------------------------------------------------------------------------------------
def _queretaro_params(params, f=1.0):
    _unknown(params, QUERETARO_DEFAULTS, "pfault_queretaro_")
    p = dict(QUERETARO_DEFAULTS)
    p.update({k: v for k, v in params.items() if v is not None})
    lx, ly, depth = QUERETARO_SIZE
    xf = p["fault_x"] = _real(p["fault_x"], "pfault_queretaro_fault_x")
    tc = p["clay_thickness"] = _real(p["clay_thickness"], "pfault_queretaro_clay_thickness")
    if not 0.05 * lx <= xf <= 0.95 * lx:
        raise InputError(f"-pfault_queretaro_fault_x: must lie in [{0.05 * lx:g}, {0.95 * lx:g}] m, got {xf:g}")
    if not 1.0 <= tc <= depth - 1.0:
        raise InputError(f"-pfault_queretaro_clay_thickness: must lie in [1, {depth - 1:g}] m, got {tc:g}")
    hf = p["fault_size"] = _real(p["fault_size"], "pfault_queretaro_fault_size")
    if not 1.0 <= hf <= _QRO_H_MAX:
        raise InputError(f"-pfault_queretaro_fault_size: must lie in [1, {_QRO_H_MAX:g}] m, got {hf:g}")
    dz = p["layer_thickness"] = _real(p["layer_thickness"], "pfault_queretaro_layer_thickness")
    if not 0.1 <= dz <= depth:
        raise InputError(f"-pfault_queretaro_layer_thickness: must lie in [0.1, {depth:g}] m, got {dz:g}")
    if p["surface_size"] is not None:
        hs = p["surface_size"] = _real(p["surface_size"], "pfault_queretaro_surface_size")
        top = min(dz, tc / f)
        if not 0.1 <= hs <= top:
            raise InputError(f"-pfault_queretaro_surface_size: must lie in [0.1, {top:.4g}] m (at most the "
                             f"layers' height, and the clay's thickness over the size factor), got {hs:g}; leave "
                             f"it out for uniform layers")
    wells = p["wells"]
    try:
        arr = np.asarray(wells, dtype=float)
    except (TypeError, ValueError):
        raise InputError("-pfault_queretaro_wells: give the well positions as x1,y1,x2,y2,... (m)") from None
    if arr.ndim == 1:
        if arr.size % 2:
            raise InputError(f"-pfault_queretaro_wells: needs pairs x1,y1,x2,y2,... (m), got {arr.size} values")
        arr = arr.reshape(-1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2 or not np.all(np.isfinite(arr)):
        raise InputError("-pfault_queretaro_wells: give the well positions as x1,y1,x2,y2,... (m)")
    if len(arr) > 50:
        raise InputError(f"-pfault_queretaro_wells: at most 50 wells, got {len(arr)}")
    for x, y in arr:
        if not (xf < x < lx and 0.0 < y < ly):
            raise InputError(f"-pfault_queretaro_wells: well ({x:g}, {y:g}) is not in the aquifer "
                             f"({xf:g} < x < {lx:g}, 0 < y < {ly:g} m)")
    p["wells"] = tuple(map(tuple, arr.tolist()))
    return p


def queretaro_mesh(size_factor: float = 1.0, **params: Any) -> SerialMesh:
    """Pre-existing fault bounding a pumped aquifer (Queretaro valley, Mexico).

    Domain 0 <= x, y <= 30 km, -50 <= z <= 0. For x < ``fault_x`` (10 km) the whole depth is ``rock``
    (the outcropping/shallow volcanic rock of the valley border); the vertical fault (named surface
    ``fault``) at x = ``fault_x`` spans the whole y length and depth and separates it from the lacustrine
    and alluvial sediments: ``clay`` from 0 to ``clay_thickness`` (20 m) over the ``sand`` aquifer down to
    50 m. ``wells`` (default :data:`QUERETARO_WELLS`: (12, 12), (12, 15), (12, 18) km, three wells in
    the aquifer 2 km from the fault, spread over its central part) only refine the mesh; nothing is
    embedded for them.

    The domain is 600 times wider than deep, and the paper's counts (57,050 nodes for 900 km^2) mean
    elements hundreds of metres wide: the land surface is triangulated in 2-D (Frontal-Delaunay) with a
    size field, and the triangles are extruded downwards into prisms split into three tetrahedra each,
    in layers ``layer_thickness`` high (times ``size_factor``, rounded to whole layers in the clay and in the
    sand; default 50/7 m: 3 in the clay, 4 in the sand at size_factor 1). Flat elements in horizontal
    layers keep the layer interfaces, the fault and the vertical resolution exact whatever the lateral
    size. ``surface_size`` (default: none) grades the layers towards the land surface: the top layer is
    ``surface_size`` high (times ``size_factor``), the layers below grow by 0.5 m per metre of depth up to the
    layers' own height (the thin rows of fault faces under the land surface, where the fault slips and opens,
    without thinning the whole depth). The fault is the extrusion of the edge the rock and sediment parts of the
    land surface share after an OCC fragment, so its triangles are shared by the tetrahedra on both sides. Lateral
    sizes
    (times ``size_factor``): ``fault_size`` (52 m) along the fault (577 segments over 30 km, x 7 layers x 2 =
    8078 fault triangles) and 40 m at the wells, growing by 0.25 m per metre of distance, at most 1 km. The
    fault's slip converges under refinement only with elements about as wide as high beside the fault
    (``fault_size`` 50/7 m, the layer thickness): with 52 m the stuck fault carries the drawdown load of a
    column of sediment as wide as the elements beside it (docs/verification.md, calibrated Queretaro).
    """
    f = _check_factor(size_factor)
    p = _queretaro_params(params, f)
    with _gmsh_model("pfault_queretaro") as gmsh:
        volumes = _queretaro_volumes(gmsh.model.occ, p, f)
        _queretaro_groups(gmsh, volumes, p)
        xf = p["fault_x"]
        terms = [f"{p['fault_size']!r} + {_QRO_GROWTH!r}*Abs(x-{xf!r})"]
        for wx, wy in p["wells"]:
            terms.append(f"{_QRO_H_WELL!r} + {_QRO_GROWTH!r}*Sqrt((x-{wx!r})*(x-{wx!r})+(y-{wy!r})*(y-{wy!r}))")
        expr = f"{_QRO_H_MAX!r}"
        for t in terms:
            expr = f"Min({expr}, {t})"
        _size_field(gmsh, f"{f!r}*{expr}")
        gmsh.model.mesh.generate(3)
        return from_gmsh_model(source="queretaro")


def _queretaro_volumes(occ, p, f):
    """The land surface (rock and sediment rectangles, fragmented along the fault's trace) extruded down through
    the clay and then the sand, in layers; returns the volumes (dim, tag)."""
    lx, ly, depth = QUERETARO_SIZE
    xf, tc = p["fault_x"], p["clay_thickness"]
    ts = depth - tc
    rock = occ.addRectangle(0.0, 0.0, 0.0, xf, ly)
    sed = occ.addRectangle(xf, 0.0, 0.0, lx - xf, ly)
    top, _ = occ.fragment([(2, rock)], [(2, sed)])
    top = sorted(dt for dt in top if dt[0] == 2)
    dz = p["layer_thickness"]
    if p["surface_size"] is None:
        clay = dict(numElements=[max(1, int(round(tc / (dz * f))))])
        sand = dict(numElements=[max(1, int(round(ts / (dz * f))))])
    else:
        z = graded_layers(p["surface_size"] * f, dz * f, _QRO_DZ_GROWTH, (tc, depth))
        clay, sand = (dict(numElements=[1] * len(b), heights=list((b - a) / (b[-1] - a)))
                      for a, b in ((0.0, z[(z > 0) & (z <= tc)]), (tc, z[z > tc])))
    out1 = occ.extrude(top, 0.0, 0.0, -tc, recombine=False, **clay)
    mid = [out1[i - 1] for i, dt in enumerate(out1) if dt[0] == 3]
    vols1 = [dt for dt in out1 if dt[0] == 3]
    out2 = occ.extrude(mid, 0.0, 0.0, -ts, recombine=False, **sand)
    vols2 = [dt for dt in out2 if dt[0] == 3]
    occ.synchronize()
    return vols1 + vols2


def graded_layers(h0: float, h_max: float, growth: float, interfaces: ArrayLike) -> np.ndarray:
    """Depths (m, from 0 down to ``interfaces[-1]``) of the boundaries of layers whose height is ``h0`` at the
    surface and grows below it with depth d as min(h_max, h0 + growth*(d - h0)): the first layer exactly ``h0``
    high, each interval between interfaces then cut into the nearest whole number of layers of that height, spaced
    evenly in the measure of the integral of 1/height, so every interface is a layer boundary."""
    interfaces = [float(z) for z in np.ravel(interfaces)]
    grid = np.linspace(0.0, interfaces[-1], 200001)
    height = np.minimum(h_max, h0 + growth * np.maximum(0.0, grid[:-1] - h0))
    count = np.concatenate(([0.0], np.cumsum(np.diff(grid) / height)))
    bounds = [0.0, h0]
    for a, b in zip([h0, *interfaces[:-1]], interfaces):
        if b <= a + 1e-9 * b:
            continue
        ca, cb = np.interp([a, b], grid, count)
        n = max(1, int(round(cb - ca)))
        bounds += list(np.interp(ca + (cb - ca) * np.arange(1, n + 1) / n, count, grid)[:-1]) + [b]
    return np.array(bounds)


def _queretaro_groups(gmsh, volumes, p):
    """Physical volumes (rock west of the fault, clay over sand east of it) and surfaces (the six sides, the
    fault)."""
    lx, ly, depth = QUERETARO_SIZE
    xf, tc = p["fault_x"], p["clay_thickness"]
    tol = 1e-6 * lx
    materials = {"clay": [], "sand": [], "rock": []}
    for _, tag in volumes:
        x, _, z = gmsh.model.occ.getCenterOfMass(3, tag)
        materials["rock" if x < xf else ("clay" if z > -tc else "sand")].append(tag)
    for name, tags in materials.items():
        _physical(gmsh, 3, tags, name)
    groups = _outer_surfaces(gmsh, (0.0, 0.0, -depth, lx, ly, 0.0), tol)
    groups["fault"] = _x_plane_surfaces(gmsh, xf, tol)
    _physical_surfaces(gmsh, groups, "queretaro_mesh")
