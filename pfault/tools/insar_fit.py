"""An InSAR displacement time series as observations of ``python -m pfault.calibrate --insar FILE``: the model's
line of sight at the product's own pixels (each forward run has ``-pfault_insar_grid FILE``: pfault.io.insar_grid),
compared date by date.

At pixel p and date t_k, whose reference date is r_k, the product measures d_k(p) = LOS(p) . (u(p, t_k) - u(p, r_k))
up to what InSAR cannot tell: a constant per date (the reference point's motion, atmospheric and orbital residuals).
The model gives m_k(p) = LOS(p) . (u(p, t_k) - u(p, r_k)), linear in time between its output times (zero before the
scene's time 0, the state at rest), at the dates placed by the scene's ``-pfault_start_date``. Either

- ``offset`` (the default): each date has an unknown offset c_k, fitted with the parameters: the weighted residual of
  date k is (m_k - d_k - c_k) / sigma with c_k the mean of m_k - d_k over the date's pixels (its least-squares value,
  eliminated exactly; one degree of freedom per date), or
- a reference point ``x,y`` (in the product's CRS): both are referred to the pixel nearest to it,
  (m_k(p) - m_k(ref)) - (d_k(p) - d_k(ref)), that pixel left out.

``sigma`` (m) is the standard deviation of a pixel's value (white noise: the pixels are taken as independent). Pixels
without a value at a date (NaN, masked) are skipped at that date; pixels off the land surface (no model value) are
skipped at every date: both are counted in calibration.json. This module does not import PETSc.
"""

from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.insar import read_netcdf
from ..io.insar_input import InsarProduct, read_insar_product

RUN_FILE = "insar_los.nc"


@dataclass(frozen=True)
class InsarSettings:
    path: str
    sigma: float                     # m
    reference: tuple | None          # (x, y) of the reference point in the product's CRS; None: a per-date offset


def parse_reference(text: str) -> tuple | None:
    """``offset`` -> None; ``x,y`` -> (x, y)."""
    if text.strip().lower() == "offset":
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--insar-reference {text}: give 'offset' (a constant per date fitted with the parameters) "
                         "or the reference point x,y in the product's CRS") from None
    return (x, y)


class InsarTerm:
    """The InSAR part of the fit: its forward-run options, and the weighted residuals of a run."""

    def __init__(self, settings: InsarSettings, start: dt.datetime, time_end: float) -> None:
        self.settings = settings
        self.product: InsarProduct = read_insar_product(settings.path)
        p = self.product
        self.seconds = np.array([(d - start).total_seconds() for d in p.dates])
        self.ref_seconds = np.array([(d - start).total_seconds() for d in p.reference])
        late = np.flatnonzero(np.maximum(self.seconds, self.ref_seconds) > time_end * (1 + 1e-12))
        if len(late):
            raise InputError(f"--insar {settings.path}: its date {p.dates[late[0]].date()} is after the scene's end "
                             f"({time_end:g} s from -pfault_start_date {start.date()}); end the product by then or "
                             "run the scene longer")
        self.ref_pixel = self._reference_pixel()
        self.used: np.ndarray | None = None          # (nt, ny, nx) bool, set by the first run
        self.offsets: np.ndarray | None = None

    def _reference_pixel(self) -> tuple | None:
        ref = self.settings.reference
        if ref is None:
            return None
        p = self.product
        i, j = int(np.argmin(np.abs(p.y - ref[1]))), int(np.argmin(np.abs(p.x - ref[0])))
        if not np.isfinite(p.values[:, i, j]).all():
            raise InputError(f"--insar-reference {ref[0]:g},{ref[1]:g}: the nearest pixel ({p.x[j]:g}, {p.y[i]:g}) "
                             "has no value at some dates; choose a pixel with a value at every date")
        return (i, j)

    @property
    def dates(self) -> int:
        return len(self.seconds)

    @property
    def nuisance(self) -> int:
        """Parameters eliminated besides the fitted ones: one offset per date in ``offset`` mode."""
        return self.dates if self.ref_pixel is None else 0

    def overrides(self) -> dict[str, str]:
        return {"pfault_insar_grid": self.product.path}

    def simulated(self, output_dir: str) -> np.ndarray:
        """(nt, ny, nx) the model's LOS at the product's dates relative to their reference dates (NaN off the land
        surface)."""
        run = read_netcdf(os.path.join(output_dir, RUN_FILE))
        if run["los_displacement"].shape[1:] != self.product.values.shape[1:]:
            raise InputError(f"{output_dir}/{RUN_FILE}: not on the pixels of {self.product.path}")
        return _at(run["time"], run["los_displacement"], self.seconds) - \
            _at(run["time"], run["los_displacement"], self.ref_seconds)

    def difference(self, output_dir: str) -> np.ndarray:
        """(nt, ny, nx) m - d referred as the settings say (NaN where not used)."""
        diff = self.simulated(output_dir) - self.product.values
        if self.ref_pixel is not None:
            i, j = self.ref_pixel
            diff = diff - diff[:, i:i + 1, j:j + 1]
            diff[:, i, j] = np.nan
        if self.used is None:
            self.used = np.isfinite(diff)
            if not self.used.any():
                raise InputError(f"--insar {self.product.path}: no pixel with a value is on the land surface")
        diff = np.where(self.used, diff, np.nan)
        if self.ref_pixel is None:
            self.offsets = np.nanmean(diff, axis=(1, 2))
            diff = diff - self.offsets[:, None, None]
        return diff

    def residual(self, output_dir: str) -> np.ndarray:
        """The weighted residuals of the used (date, pixel) pairs, in a fixed order."""
        return self.difference(output_dir)[self.used] / self.settings.sigma

    def count(self) -> int:
        return int(self.used.sum()) if self.used is not None else int(np.isfinite(self.product.values).sum())

    def summary(self) -> dict[str, Any]:
        p = self.product
        used = self.used if self.used is not None else np.isfinite(p.values)
        return {"file": p.path, "dates": [d.isoformat() for d in p.dates], "sigma_m": self.settings.sigma,
                "reference": "offset per date" if self.ref_pixel is None else
                {"x": float(p.x[self.ref_pixel[1]]), "y": float(p.y[self.ref_pixel[0]])},
                "pixels": int(p.values[0].size), "values_used": int(used.sum()),
                "values_skipped_no_data": int((~np.isfinite(p.values)).sum()),
                "values_skipped_off_land_surface": int((np.isfinite(p.values) & ~used).sum()),
                "offsets_m": None if self.offsets is None else [float(c) for c in self.offsets]}


def _at(times: np.ndarray, maps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Maps (nt, ...) linear in time between ``times`` at each of ``t``; before the first time, the first map (the
    initial state); the run ends after every t."""
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1)
    j = np.minimum(i + 1, len(times) - 1)
    span = np.where(j > i, times[j] - times[i], 1.0)
    w = np.clip((t - times[i]) / span, 0.0, 1.0)[:, None, None]
    return (1.0 - w) * maps[i] + w * maps[j]
