"""config/wuxi_fissure.opts: Wuxi's fissure plane a candidate surface of the top clay (tensile strength and cohesion
20 kPa while intact, c = 0 once broken), at size factor 2 (938 fault triangles in one row down to the crest).

Until a face breaks, the scene is the glued one (the plane held by a cohesion of 100 MPa): so the first break
comes in the first step at whose end a glued face exceeds its strength (effective normal traction above 20 kPa,
or shear above c - t_N tan(phi)), and no earlier. By 10 years the glued tension is five times the strength over the
whole plane: every face has broken, and with every face open the end state is the plain scene's (config/wuxi.opts,
c = 0 from the start). The fissure run is on 2 ranks, the glued and plain ones on 1.

Skipped until the faults' tensile strength is an option of pfault (-pfault_fault_<name>_tensile_strength).
"""

import numpy as np
import pytest

from conftest import WUXI, run_scene
from pfault.post import fissures, meshes

SCENE = "config/wuxi_fissure.opts"
COARSE = ["-pfault_mesh_size_factor", "2"]
STRENGTH, COHESION, FRICTION = 20e3, 20e3, np.radians(30.0)


def _declared():
    from pfault.options import spec_for
    return spec_for("pfault_fault_fissure_tensile_strength") is not None


pytestmark = pytest.mark.skipif(not _declared(), reason="-pfault_fault_<name>_tensile_strength is not an option of "
                                                        "pfault yet (faults that break, issue 32)")


def _fault_steps(run_dir):
    """[(time, {dataset: array})] of fault.h5's output times."""
    import h5py
    with h5py.File(str(run_dir / "fault.h5"), "r") as f:
        return [(float(g.attrs["time"]), {k: g[k][()] for k in g})
                for g in (f["steps"][k] for k in sorted(f["steps"]))]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("wuxi_fissure")
    out = {}
    out["fissure"] = run_scene(SCENE, base / "fissure", ranks=2, extra=[*COARSE, "-pfault_figures", "true"])[1]
    out["glued"] = run_scene(WUXI, base / "glued", extra=[*COARSE, "-pfault_fault_fissure_cohesion", "100*MPa"])[1]
    out["plain"] = run_scene(WUXI, base / "plain", extra=COARSE)[1]
    return base, out


def test_breaks_first_where_the_glued_plane_exceeds_its_strength(runs):
    """The first break: after the last output time at which no glued face exceeds its strength, not after the
    first at which one does; the faces broken then include one that exceeds it in the glued state."""
    base, s = runs
    glued = _fault_steps(base / "glued")
    over = []
    for t, d in glued:
        tn = d["traction_normal_effective"]
        ts = np.linalg.norm(d["traction_shear"], axis=1)
        over.append((tn > STRENGTH) | (ts > COHESION - tn * np.tan(FRICTION)))
    # output time 0 is the initial (geostatic) state, which no step judges: faces are judged at the end of each
    # step, so one over its strength there (coarse Wuxi: one face, 22.1 kPa of tension above the buried ridge against
    # the 20 kPa strength) breaks in the first step
    assert glued[0][0] == 0.0 and over[0].sum() <= 1
    k = next(i for i, o in enumerate(over) if i > 0 and o.any())
    first = s["fissure"]["faults"]["fissure"]["first_break_time_s"]
    assert glued[k - 1][0] < first <= glued[k][0]
    broken = {t: d for t, d in _fault_steps(base / "fissure")}[glued[k][0]]["broken"] != 0
    assert broken.any() and (broken & over[k]).any()
    assert not any(d["broken"].any() for t, d in _fault_steps(base / "fissure") if t < glued[k][0])


def test_whole_plane_broken_and_open_at_the_end_as_the_plain_scene(runs):
    """At 10 years: every face broken (area, depth 5 m, length 5,000 m of the plane), the fissure at the land
    surface from its first break on (it starts there), at most 15 Newton iterations in a step, the opening and
    subsidence of the plain scene."""
    base, s = runs
    fis = s["fissure"]
    assert fis["converged"] and max(r["newton_its"] for r in fis["steps"]) <= 15
    last = fissures.read_breaks(str(base / "fissure"))
    assert last.broken.all() and np.all(np.isfinite(last.break_time))
    _, area, _ = meshes.face_geometry(last.points, last.faces)
    f = fis["faults"]["fissure"]
    assert f["broken_area_m2"] == pytest.approx(area.sum(), rel=1e-9)
    assert f["broken_area_m2"] == pytest.approx(5.0 * 5000.0, rel=1e-9)
    assert f["broken_depth_m"] == pytest.approx(5.0, rel=1e-9)
    assert f["broken_length_m"] == pytest.approx(5000.0, rel=1e-9)
    m = fissures.measures(str(base / "fissure"), last)["fissure"]
    assert m["surface_break_time_s"] == f["first_break_time_s"]
    for key in ("max_fault_opening_m", "max_subsidence_m"):
        assert fis[key] == pytest.approx(s["plain"][key], rel=1e-6), key
    assert (base / "fissure" / fissures.FIGURE).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
