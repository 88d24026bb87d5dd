"""The recorder's versioned schemas: the haptic-rate sample stream, discrete events, the header.

Samples are flat float columns (one per component) so pandas, polars and DuckDB
read them without nested types; units are in each field's metadata (SI).
"""

from __future__ import annotations

import pyarrow as pa

from sim.errors import VascsimError
from sim.forceps import FORCEPS_EVENT_KINDS
from sim.needle.interaction import EVENT_KINDS as NEEDLE_EVENT_KINDS
from sim.runtime.shared import EVENT_CODES as RUNTIME_EVENT_KINDS

SCHEMA_VERSION = 5
"""2 added the tissue's reaction force on the needle (``reaction_x/y/z``); 3 the tip's velocity vector
(``tip_vx/vy/vz``, where 2 stored only its speed) and dropped ``compute`` (written 0 in every sample);
4 the subordinate hand's forceps: their tool point and orientation, jaws, the grasped tissue's
displacement and the forceps' force on it (``sub_x`` ... ``grasp_fz``); 5 how each hand's pose was
obtained (``tool_tracking``, ``sub_tracking``: measured, or a camera's predicted or held pose). Older
files are read with the columns they lack NaN (not recorded), their tracking columns 0 (every device
before the camera measured its pose), and without ``compute``."""
READABLE_VERSIONS = (1, 2, 3, 4, 5)


class RecorderError(VascsimError):
    """A session file is missing, malformed, of an unknown version, or fails its checksum."""


# (name, unit, description). Order defines the row layout used by SessionWriter.record.
SAMPLE_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("time", "s", "session time"),
    ("tool_x", "m", "dominant tool position"),
    ("tool_y", "m", ""),
    ("tool_z", "m", ""),
    ("tool_qw", "1", "dominant tool orientation quaternion"),
    ("tool_qx", "1", ""),
    ("tool_qy", "1", ""),
    ("tool_qz", "1", ""),
    ("tool_vx", "m/s", "dominant tool velocity"),
    ("tool_vy", "m/s", ""),
    ("tool_vz", "m/s", ""),
    ("tip_x", "m", "needle tip position"),
    ("tip_y", "m", ""),
    ("tip_z", "m", ""),
    ("tip_speed", "m/s", "needle tip speed"),
    ("tangent_x", "1", "needle tip direction"),
    ("tangent_y", "1", ""),
    ("tangent_z", "1", ""),
    ("force_x", "N", "force sent to the device"),
    ("force_y", "N", ""),
    ("force_z", "N", ""),
    ("contact_triangle", "1", "exterior triangle in contact, -1 for none"),
    ("bary_0", "1", "barycentric coordinates of the contact"),
    ("bary_1", "1", ""),
    ("bary_2", "1", ""),
    ("local_stress", "Pa", "max von Mises stress around the contact"),
    ("stretch", "1", "stretch statistic lambda"),
    ("pierced", "1", "needle state: 0 free, 1 contact, 2 pierced, 3 exited"),
    ("sub_dx", "m", "subordinate-hand displacement"),
    ("sub_dy", "m", ""),
    ("sub_dz", "m", ""),
    ("grip", "1", "needle-holder grip closed (1) or open (0)"),
    ("period", "s", "haptic loop period"),
    ("reaction_x", "N", "the tissue's force on the needle (before the device's scale, clamp and rate limit)"),
    ("reaction_y", "N", ""),
    ("reaction_z", "N", ""),
    ("tip_vx", "m/s", "needle tip velocity (between the last two FEM steps)"),
    ("tip_vy", "m/s", ""),
    ("tip_vz", "m/s", ""),
    ("sub_x", "m", "subordinate tool (forceps jaw) position; NaN without a subordinate hand"),
    ("sub_y", "m", ""),
    ("sub_z", "m", ""),
    ("sub_qw", "1", "subordinate tool orientation quaternion"),
    ("sub_qx", "1", ""),
    ("sub_qy", "1", ""),
    ("sub_qz", "1", ""),
    ("sub_jaw", "1", "forceps jaws closed (1) or open (0)"),
    ("grasp_dx", "m", "displacement of the tissue the forceps hold (0 when they hold none)"),
    ("grasp_dy", "m", ""),
    ("grasp_dz", "m", ""),
    ("grasp_fx", "N", "the forceps' force on the tissue"),
    ("grasp_fy", "N", ""),
    ("grasp_fz", "N", ""),
    ("tool_tracking", "1", "dominant tool pose: 0 measured, 1 predicted (camera frames late), 2 held (lost)"),
    ("sub_tracking", "1", "subordinate tool pose: 0 measured, 1 predicted, 2 held"),
)
TRACKING_COLUMNS = ("tool_tracking", "sub_tracking")
REACTION_COLUMNS = ("reaction_x", "reaction_y", "reaction_z")
VELOCITY_COLUMNS = ("tip_vx", "tip_vy", "tip_vz")
SAMPLE_COLUMNS = tuple(name for name, _, _ in SAMPLE_FIELDS)
COLUMN = {name: i for i, name in enumerate(SAMPLE_COLUMNS)}
SUBORDINATE_COLUMNS = SAMPLE_COLUMNS[COLUMN["sub_x"] : COLUMN["grasp_fz"] + 1]
"""The columns schema version 4 added: the subordinate hand's forceps."""


def column_span(*names: str) -> slice:
    """The row slice holding ``names``, which must be adjacent and in this order (e.g. a vector's
    three components): how code that fills a sample row names its places instead of counting them."""
    first = COLUMN[names[0]]
    if tuple(SAMPLE_COLUMNS[first : first + len(names)]) != names:
        raise RecorderError(f"sample columns {', '.join(names)} are not adjacent in this order")
    return slice(first, first + len(names))


INTEGER_COLUMNS = {
    "contact_triangle": pa.int32(),
    "pierced": pa.int8(),
    "grip": pa.int8(),
    "tool_tracking": pa.int8(),
    "sub_tracking": pa.int8(),
}


def _field(name: str, unit: str, description: str) -> pa.Field:
    kind = INTEGER_COLUMNS.get(name, pa.float64())
    return pa.field(name, kind, nullable=False, metadata={"unit": unit, "description": description})


SAMPLE_SCHEMA = pa.schema(
    [_field(*spec) for spec in SAMPLE_FIELDS],
    metadata={"vascsim.schema": "samples", "vascsim.schema_version": str(SCHEMA_VERSION)},
)
_V4_FIELDS = tuple(spec for spec in SAMPLE_FIELDS if spec[0] not in TRACKING_COLUMNS)
_V3_FIELDS = tuple(spec for spec in _V4_FIELDS if spec[0] not in SUBORDINATE_COLUMNS)
_V2_FIELDS = (
    *(spec for spec in _V3_FIELDS if spec[0] not in (*REACTION_COLUMNS, *VELOCITY_COLUMNS)),
    ("compute", "s", "haptic step compute time"),
    *(spec for spec in _V3_FIELDS if spec[0] in REACTION_COLUMNS),
)
SAMPLE_SCHEMA_V2 = pa.schema(
    [_field(*spec) for spec in _V2_FIELDS],
    metadata={"vascsim.schema": "samples", "vascsim.schema_version": "2"},
)
SAMPLE_SCHEMA_V1 = pa.schema(
    [_field(*spec) for spec in _V2_FIELDS if spec[0] not in REACTION_COLUMNS],
    metadata={"vascsim.schema": "samples", "vascsim.schema_version": "1"},
)
SAMPLE_SCHEMA_V3 = pa.schema(
    [_field(*spec) for spec in _V3_FIELDS],
    metadata={"vascsim.schema": "samples", "vascsim.schema_version": "3"},
)
SAMPLE_SCHEMA_V4 = pa.schema(
    [_field(*spec) for spec in _V4_FIELDS],
    metadata={"vascsim.schema": "samples", "vascsim.schema_version": "4"},
)
OLDER_SAMPLE_SCHEMAS = {1: SAMPLE_SCHEMA_V1, 2: SAMPLE_SCHEMA_V2, 3: SAMPLE_SCHEMA_V3, 4: SAMPLE_SCHEMA_V4}


def upgraded_samples(table: pa.Table) -> pa.Table:
    """An older samples table in the current layout: the columns it lacks added as NaN (not recorded),
    the tracking columns as 0 (measured), the ones the current one dropped (``compute``) left out."""
    import numpy as np

    for field in SAMPLE_SCHEMA:
        if field.name not in table.column_names:
            if field.name in TRACKING_COLUMNS:
                values = pa.array(np.zeros(table.num_rows, dtype=np.int8), type=field.type)
            else:
                values = pa.array(np.full(table.num_rows, np.nan))
            table = table.append_column(field.with_type(values.type), values)
    return table.select(list(SAMPLE_COLUMNS)).cast(SAMPLE_SCHEMA)


# Every kind the simulator emits (needle events, runtime events), plus the recorder's own.
EVENT_KINDS = tuple(
    dict.fromkeys(
        (
            *NEEDLE_EVENT_KINDS,
            *FORCEPS_EVENT_KINDS,
            *RUNTIME_EVENT_KINDS,
            "stopped",
            "queue_overflow",
            "marker",
            "annotation",
        )
    )
)

EVENT_SCHEMA = pa.schema(
    [
        pa.field("time", pa.float64(), nullable=False, metadata={"unit": "s"}),
        pa.field("kind", pa.string(), nullable=False),
        pa.field("triangle", pa.int32(), nullable=False),
        pa.field("bary_0", pa.float64()),
        pa.field("bary_1", pa.float64()),
        pa.field("bary_2", pa.float64()),
        pa.field("entry_angle_deg", pa.float64(), metadata={"unit": "deg"}),
        pa.field("tip_speed", pa.float64(), metadata={"unit": "m/s"}),
        pa.field("layer", pa.string()),
        pa.field("detail", pa.string()),
    ],
    metadata={"vascsim.schema": "events", "vascsim.schema_version": str(SCHEMA_VERSION)},
)
