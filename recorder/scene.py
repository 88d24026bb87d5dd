"""The scene stream: what the graphics layer saw, once per graphics frame (30 Hz by default).

Per frame: time (s), needle state, tip speed (m/s), the reaction force on the needle
(N), the needle's vertices (m, tip first), the tissue drive (contact node ids and
their intended displacements, m) and, with a subordinate hand, its grasp (the grasped
node ids and the forceps' force on each, N) and its jaws (point, m, and closed). With
it a replay renders any frame straight from the recording, without re-running the
simulation; a scene recorded before the grasp columns reads with none. It is written when the session closes,
verified and checksummed like the other files; a crashed session has none, and its
replay re-simulates instead.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from recorder.layout import SCENE_FILE, read_checked, sha256_of
from recorder.schema import RecorderError

SCENE_SCHEMA = pa.schema(
    [
        pa.field("time", pa.float64(), metadata={"unit": "s"}),
        pa.field(
            "state",
            pa.int8(),
            metadata={"unit": "1", "description": "0 free, 1 contact, 2 pierced, 3 exited"},
        ),
        pa.field("tip_speed", pa.float64(), metadata={"unit": "m/s"}),
        pa.field(
            "force", pa.list_(pa.float64(), 3), metadata={"unit": "N", "description": "reaction on needle"}
        ),
        pa.field(
            "needle", pa.list_(pa.float64()), metadata={"unit": "m", "description": "vertices xyz, tip first"}
        ),
        pa.field("drive_nodes", pa.list_(pa.int32()), metadata={"description": "driven tissue node ids"}),
        pa.field(
            "drive_intended", pa.list_(pa.float64()), metadata={"unit": "m", "description": "xyz per node"}
        ),
        pa.field(
            "drive_soft_share",
            pa.float64(),
            metadata={"unit": "1", "description": "biphase soft share of the drive (null: from its strain)"},
        ),
        pa.field(
            "grasp_nodes", pa.list_(pa.int32()), metadata={"description": "tissue node ids the forceps hold"}
        ),
        pa.field(
            "grasp_forces",
            pa.list_(pa.float64()),
            metadata={"unit": "N", "description": "the forceps' force on each grasped node, xyz per node"},
        ),
        pa.field(
            "jaws",
            pa.list_(pa.float64()),
            metadata={"unit": "m", "description": "jaw point xyz (empty: one hand)"},
        ),
        pa.field(
            "jaws_closed",
            pa.int8(),
            metadata={"unit": "1", "description": "1 closed, 0 open, null: one hand"},
        ),
    ],
    metadata={"stream": "scene"},
)
GRASP_FIELDS = ("grasp_nodes", "grasp_forces", "jaws", "jaws_closed")
_SCENE_SCHEMA_BEFORE_GRASP = pa.schema(list(SCENE_SCHEMA)[:-4], metadata=SCENE_SCHEMA.metadata)
_SCENE_SCHEMA_BEFORE_SHARE = pa.schema(list(SCENE_SCHEMA)[:-5], metadata=SCENE_SCHEMA.metadata)


class SceneLog:
    """Collects scene frames in memory (a 10-minute session at 30 Hz is a few MB)."""

    def __init__(self) -> None:
        self._rows: list[tuple] = []

    def add(
        self,
        time: float,
        state: int,
        tip_speed: float,
        force: NDArray[np.float64],
        needle: NDArray[np.float64],
        drive: tuple[NDArray[np.int64], NDArray[np.float64]] | None,
        soft_share: float = math.nan,
        grasp: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
        jaws: tuple[NDArray[np.float64], bool] | None = None,
    ) -> None:
        nodes, intended = (np.zeros(0, np.int32), np.zeros(0)) if drive is None else drive
        held, pulls = (np.zeros(0, np.int32), np.zeros(0)) if grasp is None else grasp
        self._rows.append(
            (
                float(time),
                int(state),
                float(tip_speed),
                np.asarray(force, dtype=np.float64).reshape(3).copy(),
                np.asarray(needle, dtype=np.float64).reshape(-1).copy(),
                np.asarray(nodes, dtype=np.int32).reshape(-1).copy(),
                np.asarray(intended, dtype=np.float64).reshape(-1).copy(),
                float(soft_share),
                np.asarray(held, dtype=np.int32).reshape(-1).copy(),
                np.asarray(pulls, dtype=np.float64).reshape(-1).copy(),
                np.zeros(0) if jaws is None else np.asarray(jaws[0], dtype=np.float64).reshape(3).copy(),
                None if jaws is None else int(bool(jaws[1])),
            )
        )

    def __len__(self) -> int:
        return len(self._rows)

    def table(self) -> pa.Table:
        columns = list(zip(*self._rows, strict=True)) if self._rows else [[] for _ in SCENE_SCHEMA]
        arrays = [
            pa.array(list(column), type=field.type, from_pandas=True)  # nan share: null (unknown)
            if field.name in ("time", "state", "tip_speed", "drive_soft_share", "jaws_closed")
            else pa.array([v.tolist() for v in column], type=field.type)
            for column, field in zip(columns, SCENE_SCHEMA, strict=True)
        ]
        return pa.Table.from_arrays(arrays, schema=SCENE_SCHEMA)


def write_scene(directory: Path, table: pa.Table) -> dict[str, Any]:
    """Write and verify ``scene.parquet``; returns its header record (file, rows, sha256)."""
    target = directory / SCENE_FILE
    temporary = directory / (SCENE_FILE + ".tmp")
    pq.write_table(table, temporary, compression="zstd")
    if not pq.read_table(temporary).equals(table):
        temporary.unlink(missing_ok=True)
        raise RecorderError(f"verification of {temporary} failed")
    temporary.replace(target)
    return {"file": SCENE_FILE, "rows": table.num_rows, "sha256": sha256_of(target)}


def read_scene(session) -> pa.Table | None:
    """The verified scene table of a :class:`recorder.Session`, or None if it was recorded without one."""
    record = session.header.get("scene")
    if record is None:
        return None
    try:
        return read_checked(session.path, SCENE_FILE, record, True, SCENE_SCHEMA)
    except RecorderError:  # recorded before the grasp columns, or before the drive's soft share
        pass
    try:
        table = read_checked(session.path, SCENE_FILE, record, True, _SCENE_SCHEMA_BEFORE_GRASP)
    except RecorderError:  # before the soft share too: derived from the drive
        table = read_checked(session.path, SCENE_FILE, record, True, _SCENE_SCHEMA_BEFORE_SHARE)
        share = pa.nulls(table.num_rows, pa.float64())
        table = table.append_column(SCENE_SCHEMA.field("drive_soft_share"), share)
    for name in GRASP_FIELDS:  # one-handed: nothing held, no jaws
        field = SCENE_SCHEMA.field(name)
        column = (
            pa.nulls(table.num_rows, field.type)
            if name == "jaws_closed"
            else pa.array([[]] * table.num_rows, type=field.type)
        )
        table = table.append_column(field, column)
    return table
