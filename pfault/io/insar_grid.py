"""The LOS raster on an InSAR product's own pixels: ``-pfault_insar_grid FILE`` (an OPERA DISP-S1 or MintPy time
series, pfault.io.insar_input), so that the model's line-of-sight displacement and the measured one share their
pixels (a difference in QGIS, the calibration's residuals).

Each pixel centre, in the product's CRS, is moved into the scene's (``-pfault_crs``, pyproj) and located on the land
surface: the triangle under it (matplotlib's trapezoid-map search on the land surface's projection) and the P1
weights of its tetrahedron there; pixels off the land surface are no-data. The LOS is the product's per pixel when it
has one (``los_east``, ``los_north``), else ``-pfault_insar_los``. ``insar_los.nc`` then has the product's x, y and
its CRS. Rank 0, NumPy; a product in a CRS when the scene has none (or the reverse) is an InputError: its pixels
cannot be placed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..checks import PIXEL_BYTES_RANK, PIXEL_BYTES_ROOT, available_memory
from ..errors import InputError, OutOfMemory
from ..georef import Transform
from ..mesh.serial import TET_FACES
from .insar import UNIT_TOL, check_los
from .insar_input import read_insar_product
from .probes import INSIDE_TOL, Located, Raster, ground_faces, mesh_to_site

OPTION = "-pfault_insar_grid"


def locate_on_surface(serial: Any, ground: str, xy: np.ndarray,
                      origin: Sequence[float] = (0.0, 0.0, 0.0)) -> tuple[np.ndarray, Located]:
    """Points ``xy`` (n, 2; site x, y) on the land surface: whether each is on it, and for those the tetrahedron
    under the surface triangle below it with the P1 weights there (in the order of the points on it)."""
    from matplotlib.tri import Triangulation
    cell, lface = ground_faces(serial, ground)
    if not len(cell):
        raise InputError(f"{OPTION}: the mesh has no land surface (-pfault_ground_surface {ground}, nor faces on its "
                         "top plane) to map")
    local = TET_FACES[lface]
    tri = serial.tets[cell[:, None], local]
    pts = mesh_to_site(serial.points[:, :2], origin)
    p = pts[tri]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    flat = np.abs(area) > 1e-9 * np.abs(area).max()                 # vertical triangles cover nothing
    cell, local, tri = cell[flat], local[flat], tri[flat]
    used, compact = np.unique(tri, return_inverse=True)
    mesh = Triangulation(pts[used, 0], pts[used, 1], compact.reshape(-1, 3))
    k = np.asarray(mesh.get_trifinder()(xy[:, 0], xy[:, 1]))
    on = k >= 0
    k = k[on]
    a, b, c = (pts[tri[k, i]] for i in range(3))
    q = xy[on]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1 = ((q[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (q[:, 1] - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (q[:, 1] - a[:, 1]) - (q[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    lam = np.clip(np.column_stack([1.0 - l1 - l2, l1, l2]), -INSIDE_TOL, None)
    weights = np.zeros((len(k), 4))
    weights[np.arange(len(k))[:, None], local[k]] = lam
    return on, Located(cell[k].astype(np.int64), weights, np.zeros(len(k), np.int64))


def _check_memory(shape: tuple, ranks_on_node: int, path: str) -> None:
    avail = available_memory()
    per_pixel = PIXEL_BYTES_ROOT + PIXEL_BYTES_RANK * (max(int(ranks_on_node), 1) - 1)
    pixels = float(np.prod(shape))
    if avail is not None and pixels * per_pixel > avail:
        raise OutOfMemory(f"{OPTION} {path}: its {shape[1]} x {shape[0]} pixels would need about "
                          f"{pixels * per_pixel / 1e9:.3g} GB, more than the {avail / 1e9:.3g} GB available; crop it "
                          "to the site or multilook it first (e.g. gdal_translate -projwin, or xarray's coarsen)")


def _pixel_los(product: Any, inside: np.ndarray, los: np.ndarray | None, path: str) -> np.ndarray:
    """(k, 3) LOS of the pixels inside (the product's), or the scene's (3,); InputError when neither is given."""
    if product.los is None:
        if los is None:
            raise InputError(f"{OPTION} {path}: the product has no line of sight (los_east, los_north); give "
                             "-pfault_insar_los e,n,u (the unit vector from the ground to the satellite)")
        return los
    v = product.los[inside]
    bad = ~np.all(np.isfinite(v), axis=1) | (v[:, 2] <= 0) | (np.abs(np.linalg.norm(v, axis=1) - 1) > UNIT_TOL)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"{OPTION} {path}: {int(bad.sum())} pixels on the land surface have no line of sight from "
                         f"the ground to the satellite in los_east, los_north (e.g. {v[i, 0]:g}, {v[i, 1]:g}); give "
                         "the product's static layers for every pixel")
    return v / np.linalg.norm(v, axis=1)[:, None]


def locate_product_pixels(serial: Any, ground: str, path: str, origin: Sequence[float], scene_crs: Any,
                          los: np.ndarray | None, ranks_on_node: int = 1) -> tuple[tuple, Located]:
    """Rank 0: ((the product's Raster, the LOS per pixel inside or (3,), the product's CRS), Located)."""
    product = read_insar_product(path, with_values=False, option=OPTION)
    if (product.crs is None) != (scene_crs is None):
        which = ("the product has no CRS (no grid mapping, no EPSG attribute) but the scene has -pfault_crs: add the "
                 "product's CRS" if product.crs is None else
                 f"the product is in {product.crs.name} but the scene has no -pfault_crs: give the scene's CRS")
        raise InputError(f"{OPTION} {path}: {which}, so that its pixels can be placed on the site")
    _check_memory((len(product.y), len(product.x)), ranks_on_node, path)
    gx, gy = np.meshgrid(product.x, product.y)
    sx, sy = Transform(product.crs, scene_crs)(gx.ravel(), gy.ravel())
    on, located = locate_on_surface(serial, ground, np.column_stack([sx, sy]), origin)
    if not on.any():
        raise InputError(f"{OPTION} {path}: none of its pixels is on the land surface (the product spans x "
                         f"{product.x[0]:g}..{product.x[-1]:g}, y {product.y[0]:g}..{product.y[-1]:g} in its CRS); "
                         "check -pfault_mesh_origin and -pfault_crs")
    inside = on.reshape(len(product.y), len(product.x))
    if los is not None and product.los is None:
        check_los(np.asarray(los))
    pixel_los = _pixel_los(product, inside, los, path)
    return (Raster(product.x, product.y, inside), pixel_los, product.crs), located
