"""The mesh cache of the gmsh generators (pfault.mesh.cache): a mesh is built once per key, read back bit for bit,
built again for another key or code version, for a file that cannot be read, and kept when several processes write
it at once; a directory that cannot be written leaves the run its mesh. In-process, no MPI, no gmsh: the builds are
a small box (pfault.mesh.box)."""

import multiprocessing
import os

import numpy as np
import pytest

from conftest import OEDOMETER, run_scene
from pfault.mesh import cache
from pfault.mesh.box import box_mesh


class Builds:
    """A build of a 2x3x2 box that counts its calls."""

    def __init__(self, cells=(2, 3, 2)):
        self.cells, self.count = cells, 0

    def __call__(self):
        self.count += 1
        return box_mesh((10.0, 20.0, 5.0), self.cells, ("clay", "sand"), (2.0,), planes=[("f", 0, 5.0, [-np.inf, np.inf, -np.inf, np.inf])])


def same(a, b):
    assert a.material_names == b.material_names and a.source == b.source
    for name in ("points", "tets", "cell_material"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    assert list(a.surfaces) == list(b.surfaces)
    for name in a.surfaces:
        assert np.array_equal(a.surfaces[name], b.surfaces[name]), name


def test_built_once_read_back_bit_for_bit(tmp_path):
    build = Builds()
    key = cache.mesh_key("box", {"size_factor": 1.0, "interfaces": (2.0,)}, version="v1")
    first = cache.cached_mesh(str(tmp_path), key, build)
    second = cache.cached_mesh(str(tmp_path), key, build)
    assert build.count == 1
    same(first, second)
    assert len(list(tmp_path.glob("*.npz"))) == 1 and not list(tmp_path.glob(".*"))     # no temporary left
    # another option, another code version: built again, in a file of its own
    cache.cached_mesh(str(tmp_path), cache.mesh_key("box", {"size_factor": 2.0}, version="v1"), build)
    cache.cached_mesh(str(tmp_path), cache.mesh_key("box", {"size_factor": 1.0, "interfaces": (2.0,)},
                                                    version="v2"), build)
    assert build.count == 3 and len(list(tmp_path.glob("*.npz"))) == 3
    # none: built every time, nothing written
    cache.cached_mesh(cache.NONE, key, build)
    assert build.count == 4


def test_key_holds_generator_options_and_code():
    key = cache.mesh_key("wuxi", {"size_factor": 1.0, "interfaces": (20.0, 50.0, 80.0)})
    assert '"code": "' + cache.code_version() + '"' in key and '"interfaces": [20.0, 50.0, 80.0]' in key
    assert cache.mesh_key("wuxi", {"size_factor": 1.0}) != cache.mesh_key("queretaro", {"size_factor": 1.0})


def test_unreadable_file_built_again(tmp_path):
    build = Builds()
    key = cache.mesh_key("box", {}, version="v")
    good = cache.cached_mesh(str(tmp_path), key, build)
    path = next(tmp_path.glob("*.npz"))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])        # cut short
    same(cache.cached_mesh(str(tmp_path), key, build), good)
    assert build.count == 2 and path.read_bytes() == data
    # a file of the same name holding another key (not this mesh's) is not taken for it
    other = cache.mesh_key("box", {"other": 1}, version="v")
    os.replace(cache._path(str(tmp_path), key), cache._path(str(tmp_path), other))
    cache.cached_mesh(str(tmp_path), key, build)
    assert build.count == 3


def test_directory_not_writable_keeps_the_mesh(tmp_path, capfd):
    blocker = tmp_path / "file"
    blocker.write_text("")
    mesh = cache.cached_mesh(str(blocker / "meshes"), cache.mesh_key("box", {}, version="v"), Builds())
    assert len(mesh.tets) == 6 * 12
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"pfault: warning: -pfault_mesh_cache {blocker / 'meshes'}: the "
                                                   "mesh is not kept")


def test_least_recently_used_pruned(tmp_path):
    build = Builds()
    keys = [cache.mesh_key("box", {"n": i}, version="v") for i in range(3)]
    for i, key in enumerate(keys):
        cache.cached_mesh(str(tmp_path), key, build)
        os.utime(cache._path(str(tmp_path), key), (1000.0 + i, 1000.0 + i))
    size = os.path.getsize(cache._path(str(tmp_path), keys[0]))
    cache.cached_mesh(str(tmp_path), keys[0], build)         # read: now the most recently used
    cache.cached_mesh(str(tmp_path), cache.mesh_key("box", {"n": 3}, version="v"), build, limit=int(2.5 * size))
    left = {p.name for p in tmp_path.glob("*.npz")}
    assert left == {os.path.basename(cache._path(str(tmp_path), k)) for k in
                    (keys[0], cache.mesh_key("box", {"n": 3}, version="v"))}


def _writer(directory, key, queue):
    mesh = Builds((3, 3, 3))()
    for _ in range(20):
        cache._store(cache._path(directory, key), key, mesh)
        read = cache._load(cache._path(directory, key), key)
        queue.put(read is not None and np.array_equal(read.tets, mesh.tets))


def test_concurrent_writers(tmp_path):
    """Four processes writing and reading the same mesh at once: every read finds a whole file."""
    key = cache.mesh_key("box", {"n": 27}, version="v")
    queue = multiprocessing.get_context("fork").Queue()
    procs = [multiprocessing.get_context("fork").Process(target=_writer, args=(str(tmp_path), key, queue))
             for _ in range(4)]
    for p in procs:
        p.start()
    results = [queue.get(timeout=60) for _ in range(80)]
    for p in procs:
        p.join(timeout=60)
    assert all(results) and len(results) == 80
    assert [p.name for p in tmp_path.iterdir()] == [os.path.basename(cache._path(str(tmp_path), key))]


@pytest.mark.parametrize("xdg", ["", "/tmp/xdg"])
def test_default_directory(monkeypatch, xdg):
    monkeypatch.setenv("XDG_CACHE_HOME", xdg)
    expected = os.path.join(xdg or os.path.expanduser("~/.cache"), "pfault", "meshes")
    assert cache.default_dir() == expected


def test_a_scene_without_a_generated_mesh_takes_the_option(tmp_path):
    """-pfault_mesh_cache names a place on the machine: a box scene (no gmsh mesh to keep) runs with it, nothing is
    written there."""
    cache_dir = tmp_path / "meshes"
    _, summary = run_scene(OEDOMETER, tmp_path / "run", extra=["-pfault_mesh_cache", str(cache_dir)])
    assert summary["converged"] and summary["max_subsidence_m"] == pytest.approx(0.8333333333333, rel=1e-9)
    assert not cache_dir.exists()
