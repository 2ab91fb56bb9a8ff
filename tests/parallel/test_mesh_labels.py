"""Point data on the distributed mesh are DMLabels that DMPlexDistribute migrates: none lost, none changed."""

import pytest

from conftest import run_script


@pytest.fixture(scope="module", params=[1, 2, 3])
def labels(request):
    return run_script("mesh_labels.py", ranks=request.param)


def test_every_label_keeps_its_points(labels):
    """Each label's strata hold as many points over all ranks as on the serial mesh (owned vertices), and every
    label has points (the scene exercises them all)."""
    assert labels["labels"] == labels["serial_labels"]
    assert set(labels["labels"]) == {"material", "boundary_face", "fault_face", "fault_side", "boundary_constraint",
                                     "displacement_boundary", "ground_surface", "fault_split"}
    assert all(labels["labels"].values())
    assert labels["multi_valued"] > 0        # cells with several boundary faces: several values on one point


def test_local_arrays_are_the_serial_data(labels):
    """Every local cell and vertex (ghosts too) reads back the serial data at its serial id; none is missing."""
    assert labels["mismatch"] == {"cells": 0, "vertices": 0}
    assert labels["missing"] == 0


def test_fault_faces_and_sides(labels):
    """Each fault face belongs to exactly one rank, with the serial face's vertices; its minus cell uses the
    minus-side dofs at the face and its plus cell the plus-side dofs at every split vertex of it."""
    assert len(labels["fault_faces"]) == 160 and set(labels["fault_faces"]) == {1}
    assert labels["face_vertices"] == 0
    assert labels["minus_side"] == 0 and labels["plus_side"] == 0
