"""Time tables that the run's time grid does not see as they were likely meant (pfault.scene.table_warning): a
table that ends before the first step (its times in bare seconds under a run in years), and a run in bare
seconds that ends before a table in years reaches its second time. A table that ends inside the run holds its
last value, as documented, without a word."""

import pytest

from pfault.scene import table_warning
from pfault.units import YEAR, parse_table

DP = "pfault_material_soil_pressure_change"


def warning(text, end_text, steps=10, name=DP, unit="Pa"):
    from pfault.units import parse_quantity
    return table_warning(name, text, parse_table(text, name, unit), parse_quantity(end_text, "pfault_time_end", "s"),
                         steps, end_text)


def test_table_in_seconds_under_a_run_in_years():
    """0:0,10:-0.1*MPa (10 s) under 10*year in 10 steps: the whole change before the first step (1 year)."""
    assert warning("0:0,10:-0.1*MPa", "10*year") == (
        f"-{DP}: the table ends at t = 10 s, before the run's first step (t = 1 year): every step takes its last "
        "value and the run sees none of its changes; its times have no unit, so they are seconds: give them in the "
        "run's unit (e.g. 10*year)")
    # the same in bare seconds for both: the unit that brings 10 nearest to the run's length
    assert warning("0:0,10:-0.1*MPa", f"{10 * YEAR!r}").endswith("(e.g. 10*year)")
    assert warning("0:0,10:-0.1*MPa", "100*day").endswith("(e.g. 10*day)")
    assert warning("0:0,10:-0.1*MPa", f"{10 * YEAR!r}*s").endswith("(e.g. 10*year)")
    # with units, before the first step: check the times or give more steps
    assert warning("0:0,2*day:-0.1*MPa", "1*year", steps=4) == (
        f"-{DP}: the table ends at t = 2 day, before the run's first step (t = 91.31 day): every step takes its last "
        "value and the run sees none of its changes; check its times, or give more steps (-pfault_time_steps)")


def test_table_that_ends_inside_the_run():
    """A table that ends inside the run holds its last value (pumping, then a pause), whatever the unit of its
    times; so does one that ends exactly at the first step."""
    assert warning("0:0,5e7:20", "10*year", name="pfault_material_soil_head_drawdown", unit="m") is None
    assert warning("0:0,5*year:20", "10*year", unit="m") is None
    assert warning("0:0,1*year:20", "10*year", unit="m") is None          # ends at the first step
    assert warning("0:0,10:-0.1*MPa", "10") is None                      # the oedometer: seconds both
    assert warning("0:0,1:-0.1*MPa", "1", steps=1) is None


def test_run_in_seconds_under_a_table_in_years():
    assert warning("0:0,10*year:20", "10", unit="m") == (
        f"-pfault_time_end 10 has no unit, so it is in seconds, and the run ends before -{DP} reaches its second time "
        "(10 year); give -pfault_time_end a unit (e.g. 10*year)")
    assert warning("0:0,10*year:20", f"{20 * YEAR!r}", unit="m") is None   # seconds that reach the table


@pytest.mark.parametrize("text", ["0:20", "0:1,1:1", "0:0,5:0"])
def test_constant_tables_say_nothing(text):
    assert warning(text, "10*year", unit="m") is None
