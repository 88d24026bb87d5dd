"""Tissue presets carry a source for every value and describe themselves from their values (issue 43,
item 6: E1 had no source, the calcified moduli were "chosen", and the description said 4.5 MPa, 15 %,
0.4 N and 0.03 N/mm while the values were 6 MPa, 12 %, 0.3 N and 0.08 N/mm)."""

import dataclasses
import re

import pytest

from sim.calibration.presets import PRESETS, describe, undocumented

CITED = re.compile(
    r"(19|20)\d\d|PAPER\.md|fitted|chosen|as the artery's|not in the paper|model choice|numerical"
)


@pytest.mark.parametrize("name", list(PRESETS))
def test_every_value_has_a_source_that_says_what_it_is(name):
    preset = PRESETS[name]
    assert undocumented(preset) == []
    for key, source in preset.sources.items():
        assert CITED.search(source), f"{name}: {key}: {source}"


def test_measured_values_cite_a_publication_and_fitted_ones_say_so():
    artery, calcified = PRESETS["porcine-artery"].sources, PRESETS["calcified"].sources
    assert artery["soft_modulus"].startswith("fitted") and "Hemmasizadeh" in artery["soft_modulus"]
    assert "not values at one stress" in artery["stiff_modulus"]
    assert "Loree" in calcified["soft_modulus"] and "1994" in calcified["soft_modulus"]
    assert "Frick" in artery["critical_speed"]
    assert re.search(r"20\d\d", artery["friction_coefficient"]) and re.search(r"20\d\d", artery["tear_force"])


@pytest.mark.parametrize("name", list(PRESETS))
def test_the_description_is_written_from_the_values(name):
    preset = PRESETS[name]
    text = preset.description
    assert text.startswith(preset.summary)
    assert f"{preset.biphase.strain_limit * 100:.0f} %" in text
    if preset.forces.puncture_force is not None:
        assert f"{preset.forces.puncture_force * 1e3:.0f} mN" in text
    changed = dataclasses.replace(preset, biphase=dataclasses.replace(preset.biphase, strain_limit=0.15))
    assert "15 %" in changed.description and changed.description != text


def test_the_artery_description_states_its_real_values():
    text = describe(PRESETS["porcine-artery"].biphase, PRESETS["porcine-artery"].forces)
    for stale in ("4.5 MPa", "15 %", "0.4 N", "0.03 N/mm"):
        assert stale not in text
    for value in ("300 kPa", "6.0 MPa", "12 %", "800 mN", "80 mN/mm", "1900 mN"):
        assert value in text
