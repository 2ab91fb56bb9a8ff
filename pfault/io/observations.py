"""Observations out in the form they are measured: station time series (pfault.io.stations) and InSAR
line-of-sight rasters (pfault.io.insar), as observers of the time loop.

``read_observation_settings`` reads their options (every rank, before the scene's options are checked);
``Observations.locate`` places the stations and the pixels in the mesh once it is built (rank 0, then shared:
a station outside the mesh is an input error before any solve); ``observers`` gives the run's observers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..errors import run_on_root
from ..paths import beside_scene
from .insar import InsarObserver, InsarSettings, read_insar_settings
from .insar import check_continuation as insar_continue
from .probes import locate_pixels
from ..soils.stations import soil_station_observers
from .stations import StationObserver, locate_stations
from .stations import check_continuation as stations_continue


@dataclass(frozen=True)
class ObservationSettings:
    stations_file: str              # -pfault_stations ('' : none)
    insar: InsarSettings | None     # -pfault_insar_los, -pfault_insar_spacing (None: no raster)


def read_observation_settings(reader: Any, scene_file: str = "") -> ObservationSettings:
    """The observation options; a relative station file is taken from the working directory, else beside the
    scene file (pfault.paths.beside_scene)."""
    return ObservationSettings(beside_scene(reader.get("pfault_stations"), scene_file), read_insar_settings(reader))


@dataclass(frozen=True)
class Observations:
    """What the observers need, located in the mesh: per kind, (rank 0's object or None, Located) or None."""
    settings: ObservationSettings
    stations: tuple | None
    pixels: tuple | None

    @classmethod
    def locate(cls, model: Any, settings: ObservationSettings) -> Observations:
        """Collective: locate the stations and the pixels on rank 0 and share where they are."""
        mpi = model.comm.tompi4py()

        def share(func, *args):
            found = run_on_root(model.comm, func, *args)
            located = mpi.bcast(found[1] if mpi.rank == 0 else None, root=0)
            return (found[0] if mpi.rank == 0 else None), located
        stations = pixels = None
        if settings.stations_file:
            stations = share(locate_stations, settings.stations_file, model.serial, model.split,
                             model.scene.mesh_origin)
        if settings.insar is not None:
            pixels = share(locate_pixels, model.serial, model.settings.ground_surface, settings.insar.spacing,
                           model.scene.mesh_origin)
        restart_dir = model.scene.restart_dir
        if restart_dir:         # the files of the run it continues are there, for the same points (before a solve)
            if stations is not None:
                run_on_root(model.comm, stations_continue, stations[0], restart_dir)
            if pixels is not None:
                run_on_root(model.comm, insar_continue, pixels[0], settings.insar.los, restart_dir)
        return cls(settings, stations, pixels)

    def observers(self, output: Any) -> list:
        """The observers of the stations and of the LOS raster the scene asks for (collective)."""
        out: list = []
        if self.stations is not None:
            out.append(StationObserver(output, *self.stations))
            out += soil_station_observers(output, self.stations[0], output.model.scene.mesh_origin)
        if self.pixels is not None:
            out.append(InsarObserver(output, *self.pixels, self.settings.insar.los))
        return out
