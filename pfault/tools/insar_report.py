"""What ``python -m pfault.calibrate --insar`` adds to its output directory (pfault.tools.insar_fit):

- ``insar_fit.nc``: on the product's pixels and dates (CF NetCDF, the product's CRS as grid mapping): ``observed``
  (m), ``model`` (the fitted run's LOS referred as the observations are: minus the fitted offset of each date, or
  referred to the reference point; NaN where no value was used), ``residual`` (model - observed) and, per date,
  ``offset`` (m: the fitted constant; absent with a reference point);
- ``insar_residual.tif``: the last date's residual as a GeoTIFF (products with a CRS);
- ``insar_fit.png``: the last date's observed, model and residual maps (mm), and at the pixel that moved most, the
  observed series against the model's.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..io.rasters import add_grid_mapping, write_geotiff


def write_insar_outputs(out: str, term: Any, fitted_dir: str) -> list[str]:
    """The files above for the run in ``fitted_dir``."""
    p = term.product
    residual = term.difference(fitted_dir)            # m - d referred, NaN where not used
    observed = np.where(term.used, p.values, np.nan)
    model = observed + residual
    written = [_netcdf(os.path.join(out, "insar_fit.nc"), term, observed, model, residual)]
    if p.crs is not None:
        written.append(write_geotiff(os.path.join(out, "insar_residual.tif"), p.x, p.y, residual[-1], p.crs,
                                     {"long_name": "model - observed LOS displacement", "units": "m",
                                      "date": p.dates[-1].isoformat()}))
    written.append(_figure(os.path.join(out, "insar_fit.png"), term, observed, model, residual))
    return written


def _netcdf(path: str, term: Any, observed: np.ndarray, model: np.ndarray, residual: np.ndarray) -> str:
    import h5netcdf
    p = term.product
    base = p.dates[0]
    with h5netcdf.File(path, "w") as nc:
        nc.attrs.update({"Conventions": "CF-1.8", "title": "InSAR fit of python -m pfault.calibrate",
                         "source": p.path})
        nc.dimensions = {"time": len(p.dates), "y": len(p.y), "x": len(p.x)}
        gm = {}
        if p.crs is not None:
            add_grid_mapping(nc, p.crs)
            gm = {"grid_mapping": "spatial_ref"}
        for name, axis in (("x", p.x), ("y", p.y)):
            v = nc.create_variable(name, (name,), np.float64, data=axis)
            v.attrs.update({"standard_name": f"projection_{name}_coordinate", "units": "m"})
        units = f"seconds since {base.strftime('%Y-%m-%dT%H:%M:%S')}"
        for name, dates in (("time", p.dates), ("reference_time", p.reference)):
            v = nc.create_variable(name, ("time",), np.float64, data=[(d - base).total_seconds() for d in dates])
            v.attrs.update({"units": units, "calendar": "standard"})
        for name, values, long in (("observed", observed, "observed LOS displacement (the values used)"),
                                   ("model", model, "fitted model's LOS displacement, referred as the observations"),
                                   ("residual", residual, "model - observed")):
            v = nc.create_variable(name, ("time", "y", "x"), np.float64, data=values, fillvalue=np.nan)
            v.attrs.update({"units": "m", "long_name": long, **gm})
        if term.offsets is not None:
            v = nc.create_variable("offset", ("time",), np.float64, data=term.offsets)
            v.attrs.update({"units": "m", "long_name": "fitted constant of each date (model - observed, mean)"})
    return path


def _figure(path: str, term: Any, observed: np.ndarray, model: np.ndarray, residual: np.ndarray) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    p = term.product
    dx, dy = p.x[1] - p.x[0], p.y[1] - p.y[0]
    extent = (p.x[0] - dx / 2, p.x[-1] + dx / 2, p.y[0] - dy / 2, p.y[-1] + dy / 2)
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    lim = float(np.nanmax(np.abs(observed[-1]))) * 1e3 or 1.0
    rlim = float(np.nanmax(np.abs(residual[-1]))) * 1e3 or 1.0
    for ax, values, title, vmax in ((axes[0, 0], observed[-1], "observed", lim), (axes[0, 1], model[-1], "model", lim),
                                    (axes[1, 0], residual[-1], "residual (model - observed)", rlim)):
        im = ax.imshow(values * 1e3, origin="lower", extent=extent, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
        fig.colorbar(im, ax=ax, label="LOS displacement (mm)")
        ax.set_title(f"{title}, {p.dates[-1].date()}", fontsize=10)
        ax.set_aspect("equal")
    i, j = np.unravel_index(int(np.nanargmax(np.abs(np.nan_to_num(observed[-1])))), observed[-1].shape)
    ax = axes[1, 1]
    ax.errorbar(p.dates, observed[:, i, j] * 1e3, yerr=term.settings.sigma * 1e3, fmt="o", ms=3, label="observed")
    ax.plot(p.dates, model[:, i, j] * 1e3, "-", label="model")
    ax.set_title(f"pixel ({p.x[j]:.0f}, {p.y[i]:.0f})", fontsize=10)
    ax.set_ylabel("LOS displacement (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
