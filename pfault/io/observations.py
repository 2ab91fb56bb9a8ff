"""Observations out in the form they are measured: station time series (pfault.io.stations) and InSAR
line-of-sight rasters (pfault.io.insar), as observers of the time loop (``StationObserver``, ``InsarObserver``).

``read_observation_settings`` reads their options (every rank, before the scene's options are checked);
``Observations.locate`` places the stations and the pixels in the mesh once it is built (rank 0, then shared:
a station outside the mesh is an input error before any solve); ``observers`` gives the run's observers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mpi4py import MPI

from ..errors import InputError, run_on_root
from ..paths import beside_scene
from ..soils.stations import soil_station_observers
from .insar import InsarSeries, InsarSettings, read_insar_settings
from .insar import check_continuation as insar_continue
from .insar_grid import locate_product_pixels
from .observers import Observer
from .probes import Located, PointProbe, Raster, locate_pixels
from .stations import StationSeries, Stations, locate_stations
from .stations import check_continuation as stations_continue


@dataclass(frozen=True)
class ObservationSettings:
    stations_file: str              # -pfault_stations ('' : none)
    insar: InsarSettings | None     # -pfault_insar_los, -pfault_insar_spacing (None: no raster)
    gis: bool = True                # -pfault_gis: the GIS layers at the end of a run with -pfault_crs


def read_observation_settings(reader: Any, scene_file: str = "") -> ObservationSettings:
    """The observation options; a relative station file is taken from the working directory, else beside the
    scene file (pfault.paths.beside_scene)."""
    spacing = reader.get("pfault_map_spacing")      # used by pfault.post.gis from options.txt
    if spacing is not None and not spacing > 0:
        raise InputError(f"-pfault_map_spacing {spacing:g}: the pixel size must be positive (m), e.g. 50*m")
    return ObservationSettings(beside_scene(reader.get("pfault_stations"), scene_file),
                               read_insar_settings(reader, scene_file), reader.get("pfault_gis"))


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
            node = mpi.Split_type(MPI.COMM_TYPE_SHARED)     # the ranks of each node: rank 0 counts those of its own
            ranks_on_node = mpi.bcast(node.size if mpi.rank == 0 else None, root=0)
            node.Free()
            if settings.insar.grid:
                georef = model.scene.georef
                pixels = share(locate_product_pixels, model.serial, model.settings.ground_surface,
                               settings.insar.grid, model.scene.mesh_origin, georef.crs if georef else None,
                               settings.insar.los, ranks_on_node)
            else:
                pixels = share(locate_pixels, model.serial, model.settings.ground_surface, settings.insar.spacing,
                               model.scene.mesh_origin, ranks_on_node)
        restart_dir = model.scene.restart_dir
        if restart_dir:         # the files of the run it continues are there, for the same points (before a solve)
            if stations is not None:
                run_on_root(model.comm, stations_continue, stations[0], restart_dir)
            if pixels is not None:
                grid = settings.insar.grid
                run_on_root(model.comm, lambda: insar_continue(pixels[0][0] if grid else pixels[0],
                                                               pixels[0][1] if grid else settings.insar.los,
                                                               restart_dir))
        return cls(settings, stations, pixels)

    def observers(self, output: Any) -> list:
        """The observers of the stations and of the LOS raster the scene asks for (collective)."""
        out: list = []
        if self.stations is not None:
            out.append(StationObserver(output, *self.stations))
            out += soil_station_observers(output, self.stations[0], output.model.scene.mesh_origin)
        if self.pixels is not None and self.settings.insar.grid:      # (raster, LOS, CRS) of the product's pixels
            found, located = self.pixels
            raster, los, crs = found if found is not None else (None, None, None)
            out.append(InsarObserver(output, raster, located, los, crs))
        elif self.pixels is not None:
            out.append(InsarObserver(output, *self.pixels, self.settings.insar.los))
        return out


class ProbeObserver(Observer):
    """An observer of the time loop that writes a series of the displacement at points (``probe``) on rank 0
    (``series``: its ``start`` opens the files, or continues those of the run a restart continues)."""

    def __init__(self, output: Any, located: Located) -> None:
        m = output.model
        self.output, self.comm = output, m.comm
        self.probe = PointProbe(m.comm, m.mesh, m.dofmap, located)
        self.series: Any = None
        self.started = False

    def start_once(self) -> None:
        """The series' files opened at the first call (rank 0; collective)."""
        if not self.started:
            out = self.output
            run_on_root(self.comm, lambda: self.series.start(out.writer.dir, out.restart_dir, out.restart_step))
            self.started = True


class StationObserver(ProbeObserver):
    """Observer of the time loop (pfault.run): the stations' displacement at time 0 (or the rows of the run a
    restart continues) and after every converged step."""

    def __init__(self, output: Any, stations: Stations | None, located: Located) -> None:
        super().__init__(output, located)
        self.series = StationSeries(stations, located.side) if self.comm.rank == 0 else None

    def step_done(self, result: Any) -> None:
        out = self.output
        self.start_once()
        if not result.record.converged:
            return
        u = self.probe.values(result.u_rel)
        run_on_root(self.comm, lambda: self.series.append(out.writer.dir, result.step, result.t, u))


class InsarObserver(ProbeObserver):
    """Observer of the time loop (pfault.run): the LOS raster at time 0 (or the times of the run a restart
    continues) and at every output time of a converged step."""

    def __init__(self, output: Any, raster: Raster | None, located: Located, los: np.ndarray,
                 crs: Any = None) -> None:
        super().__init__(output, located)
        georef = output.model.scene.georef
        crs = crs if crs is not None else (georef.crs if georef is not None else None)
        start = georef.start if georef is not None else None
        self.series = InsarSeries(raster, los, crs, start) if self.comm.rank == 0 else None

    def step_done(self, result: Any) -> None:
        out = self.output
        self.start_once()
        if not (result.output and result.record.converged):
            return
        u = self.probe.values(result.u_rel)
        run_on_root(self.comm, lambda: self.series.append(out.writer.dir, result.step, result.t, u))
