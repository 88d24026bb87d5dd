"""Dask batch metrics on a local two-worker cluster equal the in-process path."""

import pandas as pd
import pytest

from metrics import compute_session_metrics
from metrics.session.batch import compute_metrics_dask
from metrics.synthetic import synthetic_study
from recorder import SessionWriter
from recorder.schema import COLUMN, SAMPLE_COLUMNS


def store(streams, directory):
    """Write synthetic streams through the real recorder, as a simulator session would be."""
    import numpy as np

    writer = SessionWriter(
        directory,
        {"session_id": streams.session_id, "participant_id": streams.participant_id, "label": streams.label},
        capacity=1 << 15,
    )
    rows = np.zeros((streams.time.size, len(SAMPLE_COLUMNS)))
    rows[:, COLUMN["time"]] = streams.time
    rows[:, [COLUMN["tool_x"], COLUMN["tool_y"], COLUMN["tool_z"]]] = streams.tool_position
    rows[:, [COLUMN["tip_x"], COLUMN["tip_y"], COLUMN["tip_z"]]] = streams.tip_position
    rows[:, [COLUMN["force_x"], COLUMN["force_y"], COLUMN["force_z"]]] = streams.force
    rows[:, [COLUMN["sub_dx"], COLUMN["sub_dy"], COLUMN["sub_dz"]]] = streams.subordinate_displacement
    rows[:, COLUMN["pierced"]] = streams.needle_state
    rows[:, COLUMN["local_stress"]] = np.nan
    rows[:, COLUMN["stretch"]] = np.nan
    for start in range(0, rows.shape[0], 4096):
        writer.record_block(rows[start : start + 4096])
    for event in streams.events.itertuples():
        writer.event(event.time, event.kind, entry_angle_deg=event.entry_angle_deg)
    writer.close()
    return directory


@pytest.mark.slow
def test_dask_local_cluster_matches_in_process(tmp_path):
    sessions = list(
        synthetic_study(experts=2, expert_sessions=2, trainees=2, trainee_sessions=2, duration=12)
    )
    paths = [store(s, tmp_path / s.session_id) for s in sessions]
    expected = compute_session_metrics(paths)
    seen = []
    result = compute_metrics_dask(paths, n_workers=2, progress=seen.append)
    pd.testing.assert_frame_equal(result, expected)
    assert len(seen) == len(paths)
    assert result.attrs["registry_version"] == expected.attrs["registry_version"]
