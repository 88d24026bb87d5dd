"""SI inside, the units a surgeon reads at the edge: one conversion every front-end uses.

Metrics are computed and stored in SI (m, m/s, m^2, Pa, N, s, deg). What a person reads is in
millimetres, mm/s, mm^2, kPa and millinewtons (suture-needle forces are 100-3000 mN, as the replay,
the live view and the tissue tools show them), times in seconds, angles in degrees, a share of time
(stored 0-1, unit "fraction") in per cent.
:func:`display_unit` and :func:`in_display_units` are the only place that says so: the CLI, the
dashboard and the report call them, so a value reads the same everywhere.
"""

from __future__ import annotations

import math

DISPLAY_UNITS: dict[str, tuple[str, float]] = {
    "m": ("mm", 1e3),
    "m/s": ("mm/s", 1e3),
    "m^2": ("mm^2", 1e6),
    "Pa": ("kPa", 1e-3),
    "N": ("mN", 1e3),
    "N/s": ("mN/s", 1e3),
    "s": ("s", 1.0),
    "deg": ("deg", 1.0),
    "1": ("", 1.0),
    "fraction": ("%", 100.0),
}
"""SI unit -> (the unit shown, the factor from SI to it)."""


def display_unit(unit: str) -> str:
    """The unit a value of SI ``unit`` is shown in ("" for a count or a ratio)."""
    return DISPLAY_UNITS.get(unit, (unit, 1.0))[0]


def in_display_units(value: float | None, unit: str) -> float | None:
    """``value`` (SI ``unit``) in its display unit; None for a missing or non-finite value."""
    if value is None or not math.isfinite(value):
        return None
    return value * DISPLAY_UNITS.get(unit, (unit, 1.0))[1]


def significant(value: float, digits: int = 3) -> str:
    """``value`` to ``digits`` significant figures as a person reads it: no exponent between 0.001 and a
    million ("3320", not "3.32e+03"; "0.0717"; "2.43"), an exponent only beyond."""
    text = f"{value:.{digits}g}"
    if "e" in text and 1.0 <= abs(value) < 1e6:
        return f"{float(text):.0f}"
    return text


def shown(value: float | None, unit: str, digits: int = 3) -> str:
    """``value`` (SI ``unit``) as text in its display unit, ``digits`` significant figures and the
    unit ("1.46 mm", "487 kPa", "3 deg"); "-" when there is none."""
    converted = in_display_units(value, unit)
    if converted is None:
        return "-"
    text = significant(converted, digits)
    label = display_unit(unit)
    return f"{text} {label}" if label else text


def interval_text(value: float, low: float, high: float, reading: str = "") -> str:
    """ "0.82 (0.55 to 0.94), good": an estimate with its interval as a person reads it."""
    if not math.isfinite(value):
        return "not estimable"
    text = f"{value:.2f}"
    if math.isfinite(low) and math.isfinite(high):
        text += f" ({low:.2f} to {high:.2f})"
    return f"{text}, {reading}" if reading else text
