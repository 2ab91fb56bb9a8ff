"""pfault.io.parallel.agree_shapes and as_columns: a rank that owns no row takes the trailing shape and dtype the
ranks holding rows give each array (the collective HDF5 calls that create a dataset need the same arguments on
every rank); ranks holding rows that disagree are an error. The other ranks are stood in for by what allgather
returns (NumPy only, no MPI)."""

import numpy as np
import pytest

from pfault.io.parallel import agree_shapes, as_columns


class Ranks:
    """allgather of this rank's description together with the other ranks' (given as arrays)."""

    def __init__(self, others):
        self.others = others

    def allgather(self, mine):
        described = [{k: (len(v) > 0, tuple(np.shape(v)[1:]), np.asarray(v).dtype.str) for k, v in other.items()}
                     for other in self.others]
        return [mine, *described]


def test_an_empty_rank_takes_the_shape_and_dtype_of_the_ranks_with_rows():
    mine = {"stress": np.zeros(0), "state": np.zeros(0), "slip": np.zeros((0, 3))}
    other = {"stress": np.ones((4, 9)), "state": np.ones(4, np.int64), "slip": np.ones((4, 3))}
    out = agree_shapes(Ranks([other]), mine)
    assert out["stress"].shape == (0, 9) and out["stress"].dtype == np.float64
    assert out["state"].shape == (0,) and out["state"].dtype == np.int64
    assert out["slip"] is mine["slip"]                       # already agreed: untouched


def test_rows_are_kept_and_ranks_with_rows_must_agree():
    mine = {"stress": np.arange(18.0).reshape(2, 9)}
    out = agree_shapes(Ranks([{"stress": np.zeros(0)}, {"stress": np.ones((3, 9))}]), mine)
    assert out["stress"] is mine["stress"]
    with pytest.raises(RuntimeError, match="stress: the ranks' values differ"):
        agree_shapes(Ranks([{"stress": np.ones((3, 6))}]), mine)


def test_no_rank_with_rows_takes_the_first_ranks_description():
    mine = {"head": np.zeros((0, 1))}
    out = agree_shapes(Ranks([{"head": np.zeros(0)}]), mine)
    assert out["head"].shape == (0, 1)


def test_as_columns_of_empty_and_full_arrays():
    assert as_columns(np.zeros((0, 3, 3))).shape == (0, 9)
    assert as_columns(np.zeros(0)).shape == (0, 1)
    assert as_columns(np.arange(6.0).reshape(2, 3)).shape == (2, 3)
    with pytest.raises(ValueError):
        np.zeros((0, 3, 3)).reshape(0, -1)                   # what as_columns replaces
