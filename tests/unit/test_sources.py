"""Pore-pressure sources as parts (pfault.sources): a source given materials whose pore pressure does not change
(``Unchanged``, -pfault_pore_pressure_unchanged_materials) is zero in their cells and the source's elsewhere, for a
groundwater model's heads and for per-material tables; it advances, records and destroys as the source does."""

import numpy as np

from pfault.physics.loading import MaterialDrawdown, Table
from pfault.sources import TableSource, Unchanged
from pfault.sources.heads import HeadsSource


def test_heads_are_zero_in_the_unchanged_cells_and_the_source_s_elsewhere():
    table = np.array([[0.0, 0.0, 0.0, 0.0], [-1e4, -2e4, -3e4, -4e4]])       # Pa at 0 and 10 s, 4 cells
    heads = HeadsSource(np.array([0.0, 10.0]), table)
    held = Unchanged(heads, np.array([False, True, False, True]))
    assert held.active and not held.has_state and held.vertex_head() is None and held.step_record() == {}
    held.advance_to(5.0)
    assert np.array_equal(held.cell_dp(5.0), [-5e3, 0.0, -1.5e4, 0.0])
    assert np.array_equal(held.cell_dp(10.0), np.where([False, True, False, True], 0.0, heads.cell_dp(10.0)))


def test_tables_are_zero_in_the_unchanged_cells():
    """Material 0 drawn down by a table, material 1 without one: holding material 1 changes nothing; the cells of
    material 0 held take no change."""
    drawdown = MaterialDrawdown([Table.from_pairs([(0.0, 0.0), (10.0, -1e5)]), None])
    cells = np.array([0, 0, 1, 1, 0])
    tables = TableSource(drawdown, cells)
    assert np.array_equal(Unchanged(tables, cells == 1).cell_dp(5.0), tables.cell_dp(5.0))
    assert np.array_equal(Unchanged(tables, np.arange(5) == 0).cell_dp(5.0), [0.0, -5e4, 0.0, 0.0, -5e4])
