"""JIGSAWS kinematics (JHU-ISI Gesture and Skill Assessment Working Set).

A task folder holds ``kinematics/AllGestures/<Task>_<Surgeon><Trial>.txt``: one row
per 30 Hz frame, 76 whitespace-separated numbers, four manipulators in the order
master-left, master-right, slave-left, slave-right, 19 values each (position xyz in
metres, rotation matrix row-major, linear velocity xyz, rotational velocity xyz,
gripper angle). ``meta_file_<Task>.txt`` has one tab-separated row per trial: the
trial name, an empty field, self-reported skill (N/I/E), the GRS total, an empty
field and the six GRS item scores (CRLF line endings).

The patient-side (slave) tools are the ones touching tissue, so the dominant tool is
slave-right and the subordinate hand is slave-left. JIGSAWS has no force, needle
or event streams; those metrics are NaN for its trials.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.streams import SessionStreams

FRAME_RATE_HZ = 30.0
COLUMNS_PER_MANIPULATOR = 19
MANIPULATORS = ("master_left", "master_right", "slave_left", "slave_right")
N_COLUMNS = COLUMNS_PER_MANIPULATOR * len(MANIPULATORS)
SKILL_LABELS = {"N": "novice", "I": "intermediate", "E": "expert"}
GRS_ITEMS = (
    "respect_for_tissue",
    "suture_needle_handling",
    "time_and_motion",
    "flow_of_operation",
    "overall_performance",
    "quality_of_final_product",
)
_TRIAL_NAME = re.compile(r"^(?P<task>.+)_(?P<surgeon>[A-Za-z]+)(?P<trial>\d+)$")


def manipulator_columns(manipulator: str) -> dict[str, slice]:
    """Column slices of one manipulator's position, rotation, velocities and gripper angle."""
    if manipulator not in MANIPULATORS:
        raise MetricsError(f"unknown JIGSAWS manipulator {manipulator!r}; one of {', '.join(MANIPULATORS)}")
    base = MANIPULATORS.index(manipulator) * COLUMNS_PER_MANIPULATOR
    return {
        "position": slice(base, base + 3),
        "rotation": slice(base + 3, base + 12),
        "linear_velocity": slice(base + 12, base + 15),
        "rotational_velocity": slice(base + 15, base + 18),
        "gripper_angle": slice(base + 18, base + 19),
    }


@dataclass(frozen=True, eq=False)
class Trial:
    """One JIGSAWS trial: identity, labels and its (n, 76) kinematic samples."""

    trial_id: str
    task: str
    participant_id: str
    trial: int
    skill_label: str
    skill_code: str
    grs: float
    grs_items: dict[str, float]
    samples: NDArray[np.float64] = field(repr=False)

    @property
    def time(self) -> NDArray[np.float64]:
        return np.arange(self.samples.shape[0]) / FRAME_RATE_HZ

    def position(self, manipulator: str) -> NDArray[np.float64]:
        return self.samples[:, manipulator_columns(manipulator)["position"]]

    def to_streams(self) -> SessionStreams:
        subordinate = self.position("slave_left")
        return SessionStreams(
            session_id=self.trial_id,
            participant_id=self.participant_id,
            label=self.skill_label,
            time=self.time,
            tool_position=self.position("slave_right"),
            subordinate_displacement=subordinate - subordinate[0],
            grip=None,
            attributes={"trial": self.trial, "grs": self.grs, "task": self.task, "source": "JIGSAWS"},
        )


def read_meta(meta_file: str | Path) -> dict[str, dict]:
    """Trial name -> {skill_code, grs, grs_items} from a JIGSAWS meta file."""
    path = Path(meta_file)
    if not path.is_file():
        raise MetricsError(f"JIGSAWS meta file {path} does not exist")
    rows = {}
    text = path.read_text(encoding="utf-8", errors="replace")
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = [f.strip() for f in line.split("\t")]
        values = [f for f in fields if f]
        if len(values) != 9:
            raise MetricsError(
                f"{path}, line {number}: expected a trial name, skill, GRS total and six GRS items "
                f"(tab-separated); found {len(values)} field(s)"
            )
        name, code, total, *items = values
        if code not in SKILL_LABELS:
            raise MetricsError(f"{path}, line {number}: skill level must be N, I or E; got {code!r}")
        try:
            grs = float(total)
            item_scores = [float(v) for v in items]
        except ValueError as error:
            raise MetricsError(f"{path}, line {number}: GRS scores must be numbers ({error})") from None
        rows[name] = {
            "skill_code": code,
            "grs": grs,
            "grs_items": dict(zip(GRS_ITEMS, item_scores, strict=True)),
        }
    return rows


def read_kinematics(path: str | Path) -> NDArray[np.float64]:
    """The (n, 76) samples of one kinematics file; errors name the file and line."""
    path = Path(path)
    try:
        data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as error:
        raise MetricsError(f"{path}: not a JIGSAWS kinematics file ({error})") from None
    if data.shape[0] == 0:
        raise MetricsError(f"{path}: no samples")
    if data.shape[1] != N_COLUMNS:
        raise MetricsError(f"{path}: expected {N_COLUMNS} columns per row, found {data.shape[1]}")
    if not np.all(np.isfinite(data)):
        row = int(np.flatnonzero(~np.all(np.isfinite(data), axis=1))[0]) + 1
        raise MetricsError(f"{path}, line {row}: non-finite value")
    return data


def load(kinematics_dir: str | Path, meta_file: str | Path) -> list[Trial]:
    """All trials of a task: ``kinematics_dir`` is the folder of ``<Task>_<Surgeon><Trial>.txt`` files.

    Give either ``.../kinematics/AllGestures`` or the task folder (its
    ``kinematics/AllGestures`` is used). Trials are sorted by surgeon and trial number;
    a kinematics file with no row in the meta file is an error.
    """
    directory = Path(kinematics_dir)
    nested = directory / "kinematics" / "AllGestures"
    if nested.is_dir():
        directory = nested
    if not directory.is_dir():
        raise MetricsError(f"JIGSAWS kinematics folder {directory} does not exist")
    meta = read_meta(meta_file)
    files = sorted(directory.glob("*.txt"))
    if not files:
        raise MetricsError(f"{directory} holds no kinematics files (<Task>_<Surgeon><Trial>.txt)")
    trials = []
    for path in files:
        match = _TRIAL_NAME.match(path.stem)
        if match is None:
            raise MetricsError(f"{path}: name is not <Task>_<Surgeon><Trial>.txt")
        if path.stem not in meta:
            raise MetricsError(f"{path}: trial {path.stem} has no row in {meta_file}")
        info = meta[path.stem]
        trials.append(
            Trial(
                trial_id=path.stem,
                task=match["task"],
                participant_id=match["surgeon"],
                trial=int(match["trial"]),
                skill_label=SKILL_LABELS[info["skill_code"]],
                skill_code=info["skill_code"],
                grs=info["grs"],
                grs_items=info["grs_items"],
                samples=read_kinematics(path),
            )
        )
    trials.sort(key=lambda t: (t.participant_id, t.trial))
    return trials
