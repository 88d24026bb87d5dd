"""Display units (issue 25's class of problem, one conversion for every front-end): SI inside, the
units a surgeon reads at the edge."""

import math

import pytest

from metrics.session.registry import REGISTRY
from metrics.units import DISPLAY_UNITS, display_unit, in_display_units, shown


def test_every_registered_unit_has_a_display_unit():
    """A new metric in an unlisted unit would be shown in SI unnoticed: refuse that here."""
    assert {m.unit for m in REGISTRY} <= set(DISPLAY_UNITS)


def test_known_conversions_by_hand():
    assert in_display_units(0.0015, "m") == pytest.approx(1.5) and display_unit("m") == "mm"
    assert in_display_units(0.004, "m/s") == pytest.approx(4.0) and display_unit("m/s") == "mm/s"
    assert in_display_units(6.8e-5, "m^2") == pytest.approx(68.0) and display_unit("m^2") == "mm^2"
    assert in_display_units(0.5, "fraction") == pytest.approx(50.0) and display_unit("fraction") == "%"
    assert in_display_units(4.87e5, "Pa") == pytest.approx(487.0) and display_unit("Pa") == "kPa"
    assert in_display_units(0.8, "N") == pytest.approx(800.0) and display_unit("N") == "mN"
    assert in_display_units(3.0, "deg") == 3.0 and shown(0.83, "N") == "830 mN"
    assert in_display_units(math.nan, "m") is None and in_display_units(None, "m") is None
    assert shown(0.00146, "m") == "1.46 mm" and shown(4.87e5, "Pa") == "487 kPa"
    assert shown(2.0, "1") == "2" and shown(None, "m") == "-"


def test_the_review_rows_carry_the_same_numbers_in_display_units():
    """sessions.scoring.review.against_band: the row a page, the CLI and the API all show."""
    from sessions.scoring.review import against_band

    band = {"entry_to_target": {"expert_q1": 0.0001, "expert_median": 0.00015, "expert_q3": 0.0002}}
    (row,) = against_band({"entry_to_target": 0.0005}, band)
    assert row["unit"] == "m" and row["value"] == 0.0005  # stored and served in SI
    assert row["display_unit"] == "mm" and row["versus_experts"] == "worse"
    assert row["display"]["value"] == pytest.approx(0.5)
    assert row["display"]["expert_q1"] == pytest.approx(0.1) and row["display"]["expert_q3"] == pytest.approx(
        0.2
    )


def test_significant_figures_read_without_an_exponent():
    from metrics.units import shown, significant

    assert significant(3324.1) == "3320" and significant(0.0717) == "0.0717" and significant(2.434) == "2.43"
    assert significant(-1234.0) == "-1230" and significant(999.5) == "1000" and significant(12.0) == "12"
    assert significant(2.5e7) == "2.5e+07"  # beyond a million an exponent is clearer
    assert shown(3.324e6, "Pa") == "3320 kPa"  # seen: "3.32e+03 kPa" on the session page
