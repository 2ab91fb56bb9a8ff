"""Options of the materials with memory (pfault.scene.read_soils): what is read per material (compression indices
or CSUB's head-based skeletal storage, the preconsolidation as a stress, a ratio or a head), that materials without
them stay as they were, and the one-line error, naming the option and the fix, of each bad input. The real
OptionReader reads a dict standing in for PETSc's options database."""

import numpy as np
import pytest

from pfault.errors import InputError
from pfault.options import OptionReader, help_text, spec_for
from pfault.physics import soil as sl
from pfault.materials.properties import FieldRef, property_name
from pfault.scene import read_materials, read_soils, soil_cell_message

P = "pfault_material_clay_"
INDEX = {P + "compression_index": "0.35", P + "recompression_index": "0.05", P + "void_ratio": "0.77",
         P + "poisson_ratio": "0.3"}
STORAGE = {P + "inelastic_skeletal_specific_storage": "4e-4", P + "elastic_skeletal_specific_storage": "2e-5",
           P + "poisson_ratio": "0.3"}
SAND = {"pfault_material_sand_young_modulus": "12*MPa", "pfault_material_sand_poisson_ratio": "0.3"}


class _Options:
    """PETSc.Options over a dict (hasName, getString, getAll: what OptionReader uses)."""

    def __init__(self, values):
        self.values = values

    def hasName(self, name):
        return name in self.values

    def getString(self, name):
        return self.values[name]

    def getAll(self):
        return dict(self.values)


def reader(values):
    db = _Options(values)
    return OptionReader(type("PETSc", (), {"Options": staticmethod(lambda: db)}))


def soils(values, geostatic=True):
    return read_soils(reader(values), ["clay", "sand"], geostatic)


def test_index_form_and_preconsolidation_kinds():
    clay, sand = soils({**INDEX, **SAND})
    assert sand is None                                        # no such options: linear elastic, unchanged
    assert (clay.form, clay.compression, clay.recompression, clay.void_ratio) == ("index", 0.35, 0.05, 0.77)
    assert (clay.preconsolidation, clay.preconsolidation_value) == ("normal", None)
    for key, text, kind, value in (("preconsolidation_stress", "300*kPa", "stress", 3e5),
                                   ("overconsolidation_ratio", "1.4", "ratio", 1.4),
                                   ("preconsolidation_head", "-5*m", "head", -5.0)):
        clay = soils({**INDEX, **SAND, P + key: text})[0]
        assert (clay.preconsolidation, clay.preconsolidation_value) == (kind, pytest.approx(value))


def test_storage_form_and_a_field():
    clay = soils({**STORAGE, **SAND})[0]
    assert (clay.form, clay.compression, clay.recompression, clay.void_ratio) == ("storage", 4e-4, 2e-5, None)
    clay = soils({**INDEX, **SAND, P + "compression_index": "field:cc.csv"})[0]
    assert isinstance(clay.compression, FieldRef)              # checked per cell once interpolated


def test_materials_without_memory_read_as_before_and_with_memory_need_no_modulus():
    values = {**INDEX, **SAND}
    mats = read_materials(reader(values), ["clay", "sand"], soil=["clay"])
    assert mats[0].young_modulus is None and mats[1].young_modulus == 12e6
    with pytest.raises(InputError, match="missing -pfault_material_clay_young_modulus"):
        read_materials(reader(values), ["clay", "sand"])


def test_option_names_resolve_to_their_own_specs():
    """The storages end like the flow model's _specific_storage: each resolves to its own declaration and range."""
    for key in ("inelastic_skeletal_specific_storage", "elastic_skeletal_specific_storage", "compression_index",
                "recompression_index"):
        assert spec_for(P + key).name == "pfault_material_<material>_" + key
        assert property_name(P + key) == key
    assert spec_for(P + "specific_storage").name.endswith("<material>_specific_storage")
    text = help_text()
    for key in ("compression_index", "preconsolidation_head", "overconsolidation_ratio",
                "inelastic_skeletal_specific_storage"):
        assert f"-pfault_material_<material>_{key}" in text


BAD = [
    ("Cr not below Cc", {**INDEX, P + "recompression_index": "0.4"}, True,
     "-pfault_material_clay_recompression_index: 0.4 is not below", "Cc/10 to Cc/5"),
    ("e0 zero", {**INDEX, P + "void_ratio": "0"}, True, "-pfault_material_clay_void_ratio: must be positive", "0"),
    ("e0 missing", {k: v for k, v in INDEX.items() if not k.endswith("void_ratio")}, True,
     "missing -pfault_material_clay_void_ratio", "e0"),
    ("Cr missing", {P + "compression_index": "0.3", P + "void_ratio": "0.8"}, True,
     "missing -pfault_material_clay_recompression_index", "give both"),
    ("modulus and indices", {**INDEX, P + "young_modulus": "8*MPa"}, True,
     "-pfault_material_clay_young_modulus:", "remove the drained modulus"),
    ("both forms", {**INDEX, **STORAGE}, True, "-pfault_material_clay_compression_index and", "keep one form"),
    ("Sske not below Sskv", {**STORAGE, P + "elastic_skeletal_specific_storage": "5e-4"}, True,
     "-pfault_material_clay_elastic_skeletal_specific_storage: 0.0005 is not below", "Sskv/50"),
    ("OCR below 1", {**INDEX, P + "overconsolidation_ratio": "0.8"}, True,
     "-pfault_material_clay_overconsolidation_ratio: 0.8 is below 1", "normally consolidated"),
    ("head above", {**INDEX, P + "preconsolidation_head": "2*m"}, True,
     "-pfault_material_clay_preconsolidation_head: 2 m lies above", "negative value"),
    ("stress not positive", {**INDEX, P + "preconsolidation_stress": "-1"}, True,
     "-pfault_material_clay_preconsolidation_stress: must be positive", "kPa"),
    ("two preconsolidations", {**INDEX, P + "overconsolidation_ratio": "1.2", P + "preconsolidation_head": "-3"},
     True, "-pfault_material_clay_overconsolidation_ratio and -pfault_material_clay_preconsolidation_head", "give one"),
    ("preconsolidation without a law", {P + "overconsolidation_ratio": "1.2", P + "young_modulus": "8e6"}, True,
     "-pfault_material_clay_overconsolidation_ratio: 'clay' has no law with memory", "or remove it"),
    ("no geostatic start", INDEX, False, "-pfault_material_clay_compression_index: a material with memory",
     "-pfault_geostatic true"),
]


@pytest.mark.parametrize("values, geostatic, start, fix", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_is_one_line_naming_the_option_and_the_fix(values, geostatic, start, fix):
    with pytest.raises(InputError) as err:
        soils({**values, **SAND}, geostatic)
    message = str(err.value)
    assert message.startswith(start) and fix in message and "\n" not in message, message


def test_cell_messages():
    """Per cell, once fields are interpolated and the initial stress known: Cr >= Cc somewhere, and cells whose
    preconsolidation stress lies below their initial vertical effective stress (the kernel's below_initial)."""
    clay = soils({**INDEX, **SAND, P + "preconsolidation_stress": "150*kPa"})[0]
    cc, cr = np.array([0.3, 0.3, 0.3]), np.array([0.05, 0.3, 0.04])
    assert "not below -pfault_material_clay_compression_index in 1 of 3 cells" in soil_cell_message(
        clay, cc, cr, np.zeros(3, bool))
    law = sl.index_law(np.full(3, 0.3), np.full(3, 0.05), np.full(3, 0.77), np.full(3, 0.3))
    sv0 = np.array([100e3, 140e3, 200e3])
    stress0 = np.zeros((3, 3, 3))
    stress0[:, 2, 2] = -sv0
    stress0[:, 0, 0] = stress0[:, 1, 1] = -0.3 / 0.7 * sv0
    below = sl.below_initial(law, stress0, sl.vertical_preconsolidation("stress", 150e3, sv0))
    message = soil_cell_message(clay, np.full(3, 0.3), np.full(3, 0.05), below)
    assert message.startswith("-pfault_material_clay_preconsolidation_stress: 1 of 3 cells of 'clay' start above")
    assert soil_cell_message(clay, np.full(3, 0.3), np.full(3, 0.05), np.zeros(3, bool)) is None
