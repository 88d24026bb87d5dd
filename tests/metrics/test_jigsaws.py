"""The JIGSAWS importer on small files written in the data set's documented format."""

import math

import numpy as np
import pytest

from metrics import MetricsError, compute_session_metrics, construct_validity
from metrics.datasets import jigsaws

TRIALS = {  # surgeon: (skill, GRS total, number of trials)
    "B": ("N", 13, 2),
    "C": ("I", 18, 2),
    "D": ("E", 25, 2),
    "E": ("E", 24, 1),
}


def write_trial(path, frames, radius, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    rows = np.zeros((frames, 76))
    angle = 2 * np.pi * t / t[-1]
    for manipulator, scale in (("slave_right", 1.0), ("slave_left", 0.2), ("master_right", 5.0)):
        columns = jigsaws.manipulator_columns(manipulator)
        rows[:, columns["position"]] = scale * np.column_stack(
            [radius * np.cos(angle), radius * np.sin(angle), 0.001 * t]
        )
        rows[:, columns["rotation"]] = np.tile(np.eye(3).ravel(), (frames, 1))
        rows[:, columns["gripper_angle"]] = rng.uniform(-1, 1, (frames, 1))
    np.savetxt(path, rows, fmt="%.6e", delimiter="    ", newline="\r\n")


@pytest.fixture
def task(tmp_path):
    folder = tmp_path / "Suturing" / "kinematics" / "AllGestures"
    folder.mkdir(parents=True)
    lines = []
    for surgeon, (skill, grs, count) in TRIALS.items():
        for trial in range(1, count + 1):
            name = f"Suturing_{surgeon}00{trial}"
            write_trial(folder / f"{name}.txt", 90 + 30 * trial, 0.01 + 0.002 * trial, hash(name) % 1000)
            items = "\t".join(str(v) for v in (2, 3, 2, 3, 2, grs - 12))
            lines.append(f"{name}\t\t{skill}\t{grs}\t\t{items}")
    meta = tmp_path / "Suturing" / "meta_file_Suturing.txt"
    meta.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return tmp_path / "Suturing", meta


def test_load_maps_trials_labels_and_samples(task):
    folder, meta = task
    trials = jigsaws.load(folder / "kinematics" / "AllGestures", meta)
    assert [t.trial_id for t in trials] == [
        "Suturing_B001", "Suturing_B002", "Suturing_C001", "Suturing_C002",
        "Suturing_D001", "Suturing_D002", "Suturing_E001",
    ]  # fmt: skip
    first = trials[0]
    assert first.participant_id == "B" and first.trial == 1 and first.skill_label == "novice"
    assert first.grs == 13 and first.grs_items["quality_of_final_product"] == 1
    assert first.samples.shape == (120, 76)
    assert jigsaws.load(folder, meta)[0].trial_id == "Suturing_B001"  # the task folder works too


def test_trials_run_through_the_metric_pipeline(task):
    folder, meta = task
    trials = jigsaws.load(folder, meta)
    table = compute_session_metrics(trials)
    assert list(table["session_id"]) == [t.trial_id for t in trials]
    assert list(table["label"]) == [t.skill_label for t in trials]
    assert list(table["grs"]) == [t.grs for t in trials]
    first = table.iloc[0]
    radius, frames = 0.012, 120
    assert first["task_time"] == pytest.approx((frames - 1) / 30)
    circle = (
        2 * np.pi * radius * np.sin(np.pi / (frames - 1)) / (np.pi / (frames - 1))
    )  # polygon of the circle
    rise = 0.001 * (frames - 1) / 30
    assert first["path_length"] == pytest.approx(math.hypot(circle, rise), rel=1e-4)
    assert first["subordinate_path_length"] == pytest.approx(0.2 * circle, rel=1e-2)
    assert math.isnan(first["peak_force"]) and math.isnan(first["entry_angle_error_deg"])
    result = construct_validity(table, "label", ("expert", "novice"), n_boot=100)
    assert result.n_participants == {"expert": 2, "novice": 1}
    assert any("Little power" in note for note in result.notes)


def test_file_without_meta_row_is_an_error(task):
    folder, meta = task
    text = meta.read_bytes().decode().replace("Suturing_E001", "Suturing_E009")
    meta.write_bytes(text.encode())
    with pytest.raises(MetricsError, match="Suturing_E001 has no row"):
        jigsaws.load(folder, meta)


def test_bad_rows_name_the_file_and_line(task):
    folder, meta = task
    path = folder / "kinematics" / "AllGestures" / "Suturing_C001.txt"
    lines = path.read_bytes().split(b"\r\n")
    lines[3] = b" ".join(lines[3].split()[:75])
    path.write_bytes(b"\r\n".join(lines))
    with pytest.raises(MetricsError, match=r"Suturing_C001\.txt"):
        jigsaws.load(folder, meta)
    meta.write_bytes(b"Suturing_B001\t\tX\t13\t\t1\t1\t1\t1\t1\t1\r\n")
    with pytest.raises(MetricsError, match=r"line 1: skill level must be N, I or E"):
        jigsaws.read_meta(meta)
    with pytest.raises(MetricsError, match="does not exist"):
        jigsaws.load(folder / "nowhere", meta)
