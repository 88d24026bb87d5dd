"""A value against the experts' band: the quartiles of the experts' sessions, read by direction.

One function per step, shared by every front-end: :func:`expert_quartiles` turns expert sessions
into a band, :func:`against_band` reads a session's values against it ("better", "within" or
"worse" by the metric's registry direction) in SI and in the units a surgeon reads. The session
page, ``vascsim sessions show``, the participant page and the report all call these.
"""

from __future__ import annotations

import math

import pandas as pd

from metrics.session.registry import REGISTRY
from metrics.study.proficiency import band_position
from metrics.units import display_unit, in_display_units

QUARTILES = ("expert_q1", "expert_median", "expert_q3")


def expert_quartiles(values: pd.DataFrame) -> dict[str, dict]:
    """Per metric, the quartiles of the experts' values: ``values`` is long (columns ``metric`` and
    ``value``, one row per session and metric); missing values are left out."""
    values = values.dropna(subset=["value"])
    if values.empty:
        return {}
    quartiles = values.groupby("metric")["value"].quantile([0.25, 0.5, 0.75]).unstack()
    return {
        name: {"expert_q1": float(q[0.25]), "expert_median": float(q[0.5]), "expert_q3": float(q[0.75])}
        for name, q in quartiles.iterrows()
    }


def against_band(values: dict[str, float | None], band: dict[str, dict]) -> list[dict]:
    """One row per metric: value, unit, direction, the expert quartiles and ``versus_experts`` (SI),
    and the same in display units (``display_unit``, ``display``: value and quartiles).

    ``versus_experts`` is "better", "within" or "worse" than the experts' interquartile band by
    the metric's registry direction (a shorter task time than every expert is better), or None
    where the value or the band is missing.
    """
    rows = []
    empty = dict.fromkeys(QUARTILES)
    for name, value in values.items():
        known = name in REGISTRY
        better = REGISTRY[name].better if known else ""
        quartiles = band.get(name, empty)
        finite = value is not None and math.isfinite(value)
        position = None
        if finite and known and quartiles["expert_q1"] is not None:
            position = band_position(value, quartiles["expert_q1"], quartiles["expert_q3"], better)
        unit = REGISTRY[name].unit if known else ""
        rows.append(
            {
                "metric": name,
                "unit": unit,
                "better": better,
                "value": value if finite else None,
                **quartiles,
                "versus_experts": position,
                # the same numbers in the units a surgeon reads (metrics.units), for every front-end
                "display_unit": display_unit(unit),
                "display": {
                    key: in_display_units(v, unit)
                    for key, v in (("value", value if finite else None), *quartiles.items())
                },
            }
        )
    return rows
