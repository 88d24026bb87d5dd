"""JSON that arrives from outside (an HTTP body, a WebSocket frame, a bundle's manifest or signature):
read one way everywhere, with limits, so hostile nesting or numbers that JSON does not have become a
one-line refusal instead of a RecursionError, a dropped connection or a traceback."""

from __future__ import annotations

import json
from typing import Any

from recorder.schema import RecorderError

MAX_DEPTH = 64
"""Deepest nesting of arrays and objects accepted: every document vascsim reads is a few levels deep."""


class JSONInputError(RecorderError, ValueError):
    """Outside JSON refused: not JSON, NaN or an infinity, or nested deeper than allowed."""


class JSONTooDeep(JSONInputError):
    """Outside JSON nested deeper than allowed (what no schema check could even be run on)."""


def _no_constant(name: str) -> Any:
    raise JSONInputError(f"holds {name}, which is not a JSON number")


def _depth(value: Any) -> int:
    """How deeply ``value`` nests arrays and objects (without recursion: the input decides the depth)."""
    deepest, pending = 0, [(value, 1)]
    while pending:
        item, level = pending.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, level)
            pending.extend(
                (child, level + 1) for child in (item.values() if isinstance(item, dict) else item)
            )
    return deepest


def parse_json(data: bytes | str, what: str, max_depth: int = MAX_DEPTH) -> Any:
    """``data`` as JSON, strictly: no NaN or infinities, at most ``max_depth`` levels of nesting.
    JSONInputError naming ``what`` ("body", "manifest.json") otherwise."""
    try:
        value = json.loads(data, parse_constant=_no_constant)
    except RecursionError:
        raise JSONTooDeep(f"{what} nests arrays or objects deeper than {max_depth} levels") from None
    except JSONInputError as error:
        raise JSONInputError(f"{what} {error}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise JSONInputError(f"{what} is not JSON: {error}") from None
    if _depth(value) > max_depth:
        raise JSONTooDeep(f"{what} nests arrays or objects deeper than {max_depth} levels")
    return value
