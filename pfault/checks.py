"""Checks of a scene made before anything is solved or written, each raising one-line errors.

- the output directory can be created and written, and its disk has room for the run's output;
- a box mesh fits this PETSc's indices and this machine's memory, and so does an InSAR raster;
- the Dirichlet conditions hold the body against rigid-body motion.

Each runs on one rank (rank 0 under ``pfault.errors.run_on_root``, which shares the verdict).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Collection, Iterator, Sequence

import numpy as np

from .errors import InputError, OutOfMemory, OutputError


# -- output directory --------------------------------------------------------------------------------
def _nearest_existing(path):
    while not os.path.lexists(path):
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    return path


def probe_output_dir(path: str) -> None:
    """The directory ``path`` can be created (or exists) and files can be written in it.

    Probed by creating and removing a temporary file in the directory, or in its nearest existing parent
    when it does not exist yet: nothing is left behind.
    """
    full = os.path.abspath(path)
    base = _nearest_existing(full)
    if not os.path.isdir(base):
        what = "it exists and is not a directory" if base == full else f"'{base}' is not a directory"
        raise OutputError(f"-pfault_output_dir {path}: {what}; remove it or choose another directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=".pfault-probe-", dir=base)
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        raise OutputError(f"-pfault_output_dir {path}: cannot create files in '{base}' ({exc.strerror}); "
                          "choose a writable directory") from None


def output_bytes(n_points: int, n_cells: int, n_fault_faces: int, n_written: int, flow: bool = False) -> int:
    """Rough size of a run's output: the mesh once, then per written step the displacement (and head) at
    the points, pore-pressure change, stress and material per cell, and ten values per fault face; and the
    checkpoint twice (the last one and the next, written beside it before it replaces it): solution and
    initial state (6 values per point, 3 per fault face each), initial stress, the faces' initial traction
    and pore pressure, the head. The land surface's series is small beside the fields'."""
    per_step = 8 * (3 + flow) * n_points + 8 * 11 * n_cells + 8 * 12 * n_fault_faces + 4096
    mesh = 8 * 3 * n_points * (2 if n_fault_faces else 1) + 8 * 4 * n_cells + 8 * 3 * n_fault_faces
    checkpoint = 8 * (2 * 6 * n_points + 2 * 3 * n_fault_faces + 9 * n_cells + 4 * n_fault_faces + flow * n_points)
    return mesh + n_written * per_step + 2 * checkpoint + 1_000_000


def _gb(nbytes):
    return f"{nbytes / 1e9:.3g} GB"


def check_output_space(path: str, nbytes: int) -> None:
    """The disk holding ``path`` (or its nearest existing parent) has ``nbytes`` free."""
    st = os.statvfs(_nearest_existing(os.path.abspath(path)))
    free = st.f_bavail * st.f_frsize
    if nbytes > free:
        raise OutputError(f"-pfault_output_dir {path}: the output needs about {_gb(nbytes)} but only {_gb(free)} "
                          "are free on its disk; free space, write fewer steps (-pfault_output_every) or choose "
                          "another directory")


# -- mesh size --------------------------------------------------------------------------------------
BYTES_PER_HEXAHEDRON = 1000   # building the serial box on rank 0: six tetrahedra and their temporaries


def available_memory() -> int | None:
    """Bytes of memory available to new allocations (Linux MemAvailable), or None if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_box_indices(cells: Sequence[int], index_bytes: int) -> None:
    """A box of ``cells`` hexahedra has fewer unknowns than PETSc's indices (``index_bytes`` = 4 or 8) count."""
    nx, ny, nz = (int(c) for c in cells)
    dofs = 3 * (nx + 1) * (ny + 1) * (nz + 1)
    if dofs > 2 ** (8 * index_bytes - 1) - 1:
        raise InputError(f"-pfault_box_cells {','.join(str(c) for c in cells)}: {dofs:.3g} displacement "
                         f"unknowns exceed the {8 * index_bytes}-bit indices of this PETSc build; use fewer cells")


def check_box_memory(cells: Sequence[int]) -> None:
    """This machine has the memory to build a box of ``cells`` hexahedra (on one rank, so that the verdict
    does not depend on when each rank looked)."""
    nx, ny, nz = (int(c) for c in cells)
    text = ",".join(str(c) for c in cells)
    need, avail = BYTES_PER_HEXAHEDRON * nx * ny * nz, available_memory()
    if avail is not None and need > avail:
        raise OutOfMemory(f"-pfault_box_cells {text}: building the mesh alone needs about {_gb(need)}, more "
                          f"than the {_gb(avail)} of memory available; use fewer cells")


# -- InSAR raster ------------------------------------------------------------------------------------
# Bytes a pixel of the LOS raster costs at the peak, measured as the resident-set peak of runs of a 2 km box
# (-pfault_box_size 2000,2000,100 -pfault_box_cells 10,10,1) at spacings 8, 2 and 1 m (62,500 to 4e6 pixels),
# summary.json's memory_peak_mib against the pixel count: rank 0, which locates the pixels in the land surface's
# triangles (pfault.io.probes.locate_pixels: its candidate pairs), 343-359 B; every other rank, which receives
# every pixel's location and evaluates its own, 204 B. Rounded up.
PIXEL_BYTES_ROOT = 400
PIXEL_BYTES_RANK = 250


def check_raster_memory(shape: Sequence[float], extent: Sequence[float], spacing: float, default: float,
                        ranks_on_node: int = 1, memory: float | None = None) -> None:
    """The LOS raster of ``shape`` (nx, ny pixels, floats: a count need not fit an integer) over the land
    surface's ``extent`` (m) at ``spacing`` fits the memory available on rank 0's node, which ``ranks_on_node``
    ranks share; otherwise OutOfMemory naming -pfault_insar_spacing, the pixels and a spacing that fits
    (``default``: the land surface's mean edge, the option's default). Before anything of it is allocated.
    ``memory``: the bytes it may take (None: the memory available on this node, ``available_memory``)."""
    avail = available_memory() if memory is None else memory
    per_pixel = PIXEL_BYTES_ROOT + PIXEL_BYTES_RANK * (max(int(ranks_on_node), 1) - 1)
    pixels = float(np.prod(shape))
    if avail is None or pixels * per_pixel <= avail:
        return
    fit = next(s for s in _round_spacings(spacing)
               if np.prod(np.ceil(np.asarray(extent) / s) + 1) * per_pixel <= avail)
    nx, ny = shape
    ranks = f"{ranks_on_node} rank{'s' if ranks_on_node > 1 else ''}"
    raise OutOfMemory(f"-pfault_insar_spacing {spacing:g} m: the raster over the land surface ({extent[0]:g} x "
                      f"{extent[1]:g} m) would have {pixels:.3g} pixels ({nx:.3g} x {ny:.3g}) and need about "
                      f"{_gb(pixels * per_pixel)} ({per_pixel} B a pixel with {ranks} on this node), "
                      f"more than the {_gb(avail)} of memory available; give a spacing of at least {fit:g} m "
                      f"(e.g. -pfault_insar_spacing {fit:g}*m; without the option, the land surface's mean edge, "
                      f"{default:.3g} m)")


def _round_spacings(spacing: float) -> Iterator[float]:
    """1, 2, 5 times powers of ten above ``spacing``, in increasing order."""
    k = int(np.floor(np.log10(spacing)))
    while True:
        for m in (1, 2, 5):
            if m * 10.0 ** k > spacing:
                yield m * 10.0 ** k
        k += 1


# -- rigid-body motion ------------------------------------------------------------------------------
def free_rigid_motions(points: np.ndarray, mask: np.ndarray) -> tuple[list[int], list[int], int]:
    """Rigid-body motions that the Dirichlet constraints leave free.

    ``mask`` holds per vertex the prescribed displacement components (bits 0-2 for x, y, z). The six
    rigid-body modes (translations, rotations about the centroid, in coordinates scaled to O(1)) are
    restricted to the constrained components; a motion is free when its restriction vanishes, i.e. it is
    in the null space of the 6x6 Gram matrix of the restrictions. Returns (free translation axes, free
    rotation axes, number of free motions), axes as indices 0-2; a rotation about an axis that is not a
    coordinate axis counts in the number only.
    """
    x = np.asarray(points, dtype=float)
    x = x - x.mean(axis=0)
    x /= max(float(np.abs(x).max()), 1e-300)
    gram = np.zeros((6, 6))
    for c in range(3):
        xs = x[(np.asarray(mask) & (1 << c)) != 0]
        rows = np.zeros((len(xs), 6))
        rows[:, c] = 1.0
        for a in range(3):                      # component c of e_a x X
            rows[:, 3 + a] = np.cross(np.eye(3)[a], xs)[:, c]
        gram += rows.T @ rows
    w, v = np.linalg.eigh(gram)
    null = v[:, w <= 1e-10 * max(np.trace(gram), 1.0)]
    if null.shape[1] == 0:
        return [], [], 0

    def in_span(basis, vec):
        if basis.shape[1] == 0:
            return False
        q, _ = np.linalg.qr(basis)
        return np.linalg.norm(q.T @ vec) > 1.0 - 1e-6

    translations = [a for a in range(3) if in_span(null, np.eye(6)[a])]
    u, s, _ = np.linalg.svd(null[3:], full_matrices=False)
    rot_basis = u[:, s > 1e-6]
    rotations = [a for a in range(3) if in_span(rot_basis, np.eye(3)[a])]
    return translations, rotations, null.shape[1]


def _axes(idx):
    names = ["xyz"[a] for a in idx]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def check_held(points: np.ndarray, mask: np.ndarray, surface_names: Collection[str]) -> None:
    """InputError naming the option to set when the boundary conditions leave a rigid-body motion free.

    The check runs on the serial mesh before the faults are split, so a fault glues the two sides: a
    block cut loose by a fault counts as held when the body as a whole is. That is what the contact
    conditions do while a face sticks or slides under friction (the Lagrange multipliers, or the penalty,
    carry the block); a block that comes fully loose by opening is a state of the solution, not of the
    constraints, and is left to the solver. Disconnected parts of a mesh are checked as one body.
    """
    translations, rotations, count = free_rigid_motions(points, np.asarray(mask) & 7)
    if count == 0:
        return
    parts = []
    if translations:
        parts.append(f"translate along {_axes(translations)}")
    if rotations:
        parts.append(f"rotate about {_axes(rotations)}")
    other = count - len(translations) - len(rotations)
    if other > 0:
        parts.append(f"move in {other} other rigid-body mode{'s' if other > 1 else ''}")
    example = "bottom" if "bottom" in surface_names else (sorted(surface_names) or ["<surface>"])[0]
    raise InputError(f"the boundary conditions leave the body free to {' and to '.join(parts)} (nothing "
                     f"holds it); fix or roll a surface, e.g. -pfault_bc_{example}_type fixed (surfaces: "
                     f"{', '.join(sorted(surface_names)) or 'none'})")
