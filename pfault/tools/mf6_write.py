"""MODFLOW 6 binary files written from NumPy: the grid file (``.dis.grb``, ``.disv.grb``) and the head file
(``.hds``), in the layouts of the MODFLOW 6 input/output guide (appendix "Binary grid file" and "Binary output
files"), as MODFLOW 6 writes them (Fortran stream access, little endian, double precision, no record markers).

pfault reads such files with flopy (pfault.sources.head_files); this writer makes test and example files where MODFLOW
6 itself is not at hand. Layer 1 is the top layer; arrays are given in MODFLOW's order (layer, row, column) or
(layer, cell2d), 0-based here, 1-based in the file where MODFLOW counts from 1 (IA, JA, IAVERT, JAVERT).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

HEADER_CHARS = 50       # "GRID DIS", "VERSION 1", "NTXT n", "LENTXT 100": 50 characters each, the last a newline
DEFINITION_CHARS = 100  # one line per variable: "NAME TYPE NDIM n dims..."


def _line(text: str, width: int) -> bytes:
    return text.encode("ascii").ljust(width - 1) + b"\n"


def _write_grb(path: str, grid_type: str, variables: list) -> None:
    """variables: (name, 'INTEGER' | 'DOUBLE', value); arrays are written flat, in the order given."""
    with open(path, "wb") as fh:
        fh.write(_line(f"GRID {grid_type}", HEADER_CHARS))
        fh.write(_line("VERSION 1", HEADER_CHARS))
        fh.write(_line(f"NTXT {len(variables)}", HEADER_CHARS))
        fh.write(_line(f"LENTXT {DEFINITION_CHARS}", HEADER_CHARS))
        for name, kind, value in variables:
            if np.ndim(value) == 0:
                fh.write(_line(f"{name} {kind} NDIM 0", DEFINITION_CHARS))
            elif name == "VERTICES":
                fh.write(_line(f"{name} {kind} NDIM 2 2 {len(value)}", DEFINITION_CHARS))
            else:
                fh.write(_line(f"{name} {kind} NDIM 1 {np.size(value)}", DEFINITION_CHARS))
        for name, kind, value in variables:
            dtype = "<i4" if kind == "INTEGER" else "<f8"
            fh.write(np.ascontiguousarray(value, dtype=dtype).tobytes())


def _structured_connectivity(nlay: int, nrow: int, ncol: int) -> tuple[np.ndarray, np.ndarray]:
    """MODFLOW's IA/JA (1-based) of a structured grid: each cell, then its face neighbours in ascending order."""
    n = nlay * nrow * ncol
    idx = np.arange(n).reshape(nlay, nrow, ncol)
    pairs = [(idx[1:], idx[:-1]), (idx[:, 1:], idx[:, :-1]), (idx[:, :, 1:], idx[:, :, :-1])]
    a = np.concatenate([np.concatenate([p.ravel(), q.ravel()]) for p, q in pairs])
    b = np.concatenate([np.concatenate([q.ravel(), p.ravel()]) for p, q in pairs])
    return _csr_with_diagonal(n, a, b)


def _csr_with_diagonal(n: int, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows = np.concatenate([np.arange(n), a])
    cols = np.concatenate([np.arange(n), b])
    key = np.where(rows == cols, -1, cols)           # the cell itself first in its row
    order = np.lexsort((key, rows))
    ia = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))])
    return ia + 1, cols[order] + 1


def write_dis_grb(path: str, delr: Iterable[float], delc: Iterable[float], top: np.ndarray, botm: np.ndarray,
                  idomain: np.ndarray | None = None, xorigin: float = 0.0, yorigin: float = 0.0,
                  angrot: float = 0.0) -> None:
    """The binary grid file of a DIS model. ``delr`` (ncol), ``delc`` (nrow), ``top`` (nrow, ncol), ``botm``
    (nlay, nrow, ncol), ``idomain`` (nlay, nrow, ncol; default all 1), the lower-left corner of the grid at
    (xorigin, yorigin), rotated by ``angrot`` degrees counter-clockwise about it."""
    delr, delc = np.asarray(delr, float), np.asarray(delc, float)
    botm = np.asarray(botm, float)
    nlay, nrow, ncol = botm.shape
    n = botm.size
    idomain = np.ones(botm.shape, int) if idomain is None else np.asarray(idomain)
    ia, ja = _structured_connectivity(nlay, nrow, ncol)
    _write_grb(path, "DIS", [
        ("NCELLS", "INTEGER", n), ("NLAY", "INTEGER", nlay), ("NROW", "INTEGER", nrow), ("NCOL", "INTEGER", ncol),
        ("NJA", "INTEGER", len(ja)), ("XORIGIN", "DOUBLE", xorigin), ("YORIGIN", "DOUBLE", yorigin),
        ("ANGROT", "DOUBLE", angrot), ("DELR", "DOUBLE", delr), ("DELC", "DOUBLE", delc),
        ("TOP", "DOUBLE", np.ravel(top)), ("BOTM", "DOUBLE", botm.ravel()), ("IA", "INTEGER", ia),
        ("JA", "INTEGER", ja), ("IDOMAIN", "INTEGER", idomain.ravel()), ("ICELLTYPE", "INTEGER", np.zeros(n))])


def write_disv_grb(path: str, vertices: np.ndarray, cells: list, top: np.ndarray, botm: np.ndarray,
                   idomain: np.ndarray | None = None, xorigin: float = 0.0, yorigin: float = 0.0,
                   angrot: float = 0.0) -> None:
    """The binary grid file of a DISV model. ``vertices`` (nvert, 2); ``cells``: per cell2d its vertex numbers
    (0-based) clockwise, as MODFLOW 6 wants them; ``top`` (ncpl), ``botm`` (nlay, ncpl), ``idomain`` (nlay,
    ncpl; default all 1). The cell centres are the vertex means; the connectivity is by shared edges."""
    vertices = np.asarray(vertices, float)
    botm = np.asarray(botm, float)
    nlay, ncpl = botm.shape
    n = botm.size
    idomain = np.ones(botm.shape, int) if idomain is None else np.asarray(idomain)
    closed = [list(c) + [c[0]] for c in cells]       # MODFLOW 6 repeats the first vertex at the end
    iavert = np.concatenate([[0], np.cumsum([len(c) for c in closed])]) + 1
    javert = np.concatenate(closed) + 1
    centre = np.array([vertices[list(c)].mean(axis=0) for c in cells])
    edges = {}
    for c, vs in enumerate(cells):
        for a, b in zip(vs, list(vs[1:]) + [vs[0]]):
            edges.setdefault((min(a, b), max(a, b)), []).append(c)
    lateral = np.array([p for p in edges.values() if len(p) == 2], int).reshape(-1, 2)
    layer = np.arange(nlay)[:, None] * ncpl
    a = np.concatenate([(lateral[:, 0] + layer).ravel(), (lateral[:, 1] + layer).ravel(),
                        np.arange(ncpl, n), np.arange(n - ncpl)])
    b = np.concatenate([(lateral[:, 1] + layer).ravel(), (lateral[:, 0] + layer).ravel(),
                        np.arange(n - ncpl), np.arange(ncpl, n)])
    ia, ja = _csr_with_diagonal(n, a, b)
    _write_grb(path, "DISV", [
        ("NCELLS", "INTEGER", n), ("NLAY", "INTEGER", nlay), ("NCPL", "INTEGER", ncpl),
        ("NVERT", "INTEGER", len(vertices)), ("NJAVERT", "INTEGER", len(javert)), ("NJA", "INTEGER", len(ja)),
        ("XORIGIN", "DOUBLE", xorigin), ("YORIGIN", "DOUBLE", yorigin), ("ANGROT", "DOUBLE", angrot),
        ("TOP", "DOUBLE", np.ravel(top)), ("BOTM", "DOUBLE", botm.ravel()), ("VERTICES", "DOUBLE", vertices),
        ("CELLX", "DOUBLE", centre[:, 0]), ("CELLY", "DOUBLE", centre[:, 1]), ("IAVERT", "INTEGER", iavert),
        ("JAVERT", "INTEGER", javert), ("IA", "INTEGER", ia), ("JA", "INTEGER", ja),
        ("IDOMAIN", "INTEGER", idomain.ravel()), ("ICELLTYPE", "INTEGER", np.zeros(n))])


HEAD_RECORD = np.dtype([("kstp", "<i4"), ("kper", "<i4"), ("pertim", "<f8"), ("totim", "<f8"), ("text", "S16"),
                        ("ncol", "<i4"), ("nrow", "<i4"), ("ilay", "<i4")])


def write_heads(path: str, times: Iterable[float], heads: np.ndarray, text: str = "HEAD",
                kper: Iterable[int] | None = None) -> None:
    """A head file: at each time (totim, the model's time unit) one record per layer, as MODFLOW 6 saves heads.
    ``heads``: (ntimes, nlay, nrow, ncol) for a DIS model, (ntimes, nlay, ncpl) for a DISV one (written as
    nrow = 1, ncol = ncpl). Each time is its own stress period of one step unless ``kper`` says otherwise
    (pertim = totim minus the period's start)."""
    times = np.asarray(list(times), float)
    heads = np.asarray(heads, float)
    if heads.ndim == 3:
        heads = heads[:, :, None, :]
    nt, nlay, nrow, ncol = heads.shape
    kper = np.arange(1, nt + 1) if kper is None else np.asarray(list(kper))
    with open(path, "wb") as fh:
        start, kstp = 0.0, 0
        for i, t in enumerate(times):
            if i > 0 and kper[i] != kper[i - 1]:
                start, kstp = times[i - 1], 0
            kstp += 1
            for k in range(nlay):
                header = np.array([(kstp, kper[i], t - start, t, text.rjust(16).encode(), ncol, nrow, k + 1)],
                                  dtype=HEAD_RECORD)
                fh.write(header.tobytes())
                fh.write(np.ascontiguousarray(heads[i, k], dtype="<f8").tobytes())
