"""Replay overlays: frames from the recorded scene stream, the tissue state per frame, golden images
through OpenImageIO, H.264/VP9 video decoded back, stress maps and plots."""

import os
from pathlib import Path

import numpy as np
import pytest

from metrics import from_recorded
from metrics.errors import MetricsError
from metrics.replay.export import ReplayCanvas, ReplaySettings, SceneReplay, _hud_lines, export_replay
from metrics.replay.plots import figure_pixels, signal_figure
from metrics.replay.reference import expert_reference
from metrics.replay.stills import stress_map
from metrics.replay.track import replay_track, scene_track
from metrics.signals.tissue import with_tissue_fields
from recorder import SessionWriter, open_session
from recorder.runtime import RuntimeRecorder
from recorder.scene import read_scene
from sessions.running.runner import SessionPlan, open_device
from sessions.synthetic import pass_parameters
from sessions.tasks import task_preset, task_spec, tissue_for
from sim.fem.fields import TissueFieldReplay
from sim.needle import Needle
from sim.render import compare_images, write_image
from sim.runtime import Simulation

FORCES = task_preset(task_spec("wall-stitch")).forces  # the calibrated needle the runner uses

GOLDEN = Path(__file__).parents[1] / "data" / "golden"


def record_pass(folder: Path, tissue, skill: float, seed: int, participant: str, label: str) -> Path:
    """One scripted stitch on the wall-stitch task, recorded as the runner records it."""
    device, duration, _ = open_device(
        "scripted", SessionPlan("s", participant, "wall-stitch", 1), None, pass_parameters(skill, seed)
    )
    header = {
        "session_id": folder.name,
        "participant_id": participant,
        "label": label,
        "task": "wall-stitch",
        "needle_forces": FORCES.as_dict(),  # as the runner records it
    }
    writer = SessionWriter(folder, header, flush_interval=0.1)
    RuntimeRecorder(writer).attach(Simulation(tissue, Needle.curved(), device, forces=FORCES)).run_simulated(
        duration
    )
    writer.close()
    return folder


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    root = tmp_path_factory.mktemp("replay")
    tissue = tissue_for(task_spec("wall-stitch"), root / "cache")
    trainee = record_pass(root / "trainee", tissue, 0.2, 11, "T01", "trainee")
    experts = [record_pass(root / f"expert{k}", tissue, 1.0, 20 + k, f"E0{k}", "expert") for k in (1, 2)]
    return tissue, open_session(trainee), [open_session(e) for e in experts]


def test_the_scene_stream_is_what_a_re_simulation_gives(recorded):
    tissue, trainee, _ = recorded
    scene = read_scene(trainee)
    assert scene is not None and scene.num_rows > 100
    from_scene = scene_track(scene, 30.0)
    again = replay_track(trainee, tissue, 30.0)
    n = min(len(from_scene), len(again))
    assert abs(len(from_scene) - len(again)) <= 1
    # the graphics layer reads the FEM snapshot up to one FEM tick (2 ms) before the haptic tick
    assert np.abs(from_scene.tip[1:n] - again.tip[1:n]).max() < 1e-4
    assert np.mean(from_scene.state[1:n] == again.state[1:n]) > 0.97


def test_re_simulation_reproduces_the_recorded_tip(recorded):
    tissue, trainee, _ = recorded
    track = replay_track(trainee, tissue, 30.0)
    time = trainee.samples.column("time").to_numpy()
    tip = np.column_stack([trainee.samples.column(c).to_numpy() for c in ("tip_x", "tip_y", "tip_z")])
    rows = np.searchsorted(time, track.times)
    # to rounding (the pose goes through a quaternion and back); frame 0 precedes the first FEM step
    np.testing.assert_allclose(track.tip[1:], tip[rows[1:]], rtol=0, atol=1e-12)


def test_tissue_state_per_frame_equals_the_models_full_solve(recorded):
    tissue, trainee, _ = recorded
    track = scene_track(read_scene(trainee), 30.0)
    fields = TissueFieldReplay(tissue)
    driven = [k for k, drive in enumerate(track.drives) if drive is not None]
    assert len(driven) > 5
    for k in driven[:: max(1, len(driven) // 6)]:
        nodes, intended, share = track.drives[k]
        assert 0.0 < share <= 1.0  # the force kernel's split, recorded with its drive
        displacement, stress = fields.state(nodes, intended, float(track.tip_speed[k]), share)
        # independently: each phase solved on its share of the drive, the answers superimposed
        soft, stiff = (
            phase.solve({int(n): f * a for n, a in zip(nodes, intended, strict=True)}, full_field=True)
            for phase, f in ((tissue.soft, share), (tissue.stiff, 1.0 - share))
        )
        np.testing.assert_allclose(displacement, soft.displacement + stiff.displacement, rtol=0, atol=1e-15)
        von_mises = tissue._fields(soft, stiff)["von_mises"][tissue.mesh.surface_elements]
        np.testing.assert_allclose(stress, von_mises, rtol=1e-9, atol=1e-9)


def _insertion_frame(recorded, size=(640, 360)):
    tissue, trainee, experts = recorded
    streams = with_tissue_fields(from_recorded(trainee), tissue)
    expert_streams = [with_tissue_fields(from_recorded(e), tissue) for e in experts]
    reference = expert_reference(streams, expert_streams)
    scene = SceneReplay(trainee, tissue, streams, 30)
    expert = SceneReplay(experts[expert_streams.index(reference.medoid)], tissue, reference.medoid, 30)
    k = int(np.searchsorted(scene.track.times, scene.pierce_time))
    expert_k = expert.index_at(float(reference.medoid_alignment.reference_time_at(scene.track.times[k])))
    canvas = ReplayCanvas(tissue.mesh, streams, ReplaySettings(size=size), ghost=True)
    bands = {name: reference.phase_band(name) for name in ("force", "tip_speed")}
    title, lines = _hud_lines(scene, k, bands)
    frame = scene.frame(k, expert.track.tip, expert.track.needle[expert_k])
    pixels = canvas.draw(float(scene.track.times[k]), frame, title, lines)
    canvas.close()
    return pixels, streams, reference


def _golden(name: str, pixels: np.ndarray, tmp_path: Path) -> tuple[int, float]:
    out = write_image(tmp_path / name, pixels)
    if os.environ.get("VASCSIM_UPDATE_GOLDEN"):
        write_image(GOLDEN / name, pixels)
    failed, mean_error, _ = compare_images(out, GOLDEN / name, fail_threshold=0.1)
    return failed, mean_error


def test_insertion_frame_matches_the_reference_image(recorded, tmp_path):
    pixels, _, _ = _insertion_frame(recorded)
    assert pixels.shape == (360, 640, 3)
    failed, mean_error = _golden("replay_insertion.png", pixels, tmp_path)
    assert failed <= 0.005 * pixels.shape[0] * pixels.shape[1], (failed, mean_error)
    assert mean_error < 0.01


def test_signal_plot_matches_the_reference_image(recorded, tmp_path):
    import matplotlib.pyplot as plt

    _, streams, reference = _insertion_frame(recorded)
    figure = signal_figure(streams, reference)
    pixels = figure_pixels(figure, dpi=60)
    plt.close(figure)
    failed, mean_error = _golden("replay_signals.png", pixels, tmp_path)
    assert failed <= 0.005 * pixels.shape[0] * pixels.shape[1], (failed, mean_error)


def test_expert_band_of_identical_experts_is_the_expert(recorded):
    tissue, _, experts = recorded
    expert = with_tissue_fields(from_recorded(experts[0]), tissue)
    reference = expert_reference(expert, [expert, expert])
    band = reference.band(expert, "tip_speed")
    np.testing.assert_allclose(band.median, expert.tip_speed, atol=1e-12)
    np.testing.assert_allclose(band.lower, band.upper, atol=1e-12)


def _decoded(path: Path):
    import av

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        codec = stream.codec_context.name
        frames = [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]
    return codec, frames


@pytest.mark.slow
@pytest.mark.parametrize(
    ("suffix", "codec", "mode"), [(".mp4", "h264", "ghost"), (".webm", "vp9", "side-by-side")]
)
def test_video_decodes_back_with_every_frame(recorded, tmp_path, suffix, codec, mode):
    tissue, trainee, experts = recorded
    out = tmp_path / f"replay{suffix}"
    seen = []
    result = export_replay(
        trainee, tissue, out, experts, ReplaySettings(fps=15, size=(320, 180), mode=mode),
        progress=lambda done, total: seen.append((done, total)), stills=tmp_path / "stills",
    )  # fmt: skip
    found, frames = _decoded(out)
    assert found == codec
    assert len(frames) == result.frames == seen[-1][0] == seen[-1][1]
    assert frames[0].shape == (180, 320, 3)
    assert np.abs(frames[5].astype(int) - frames[-5].astype(int)).mean() > 1.0  # it moves
    if suffix == ".mp4":
        data = out.read_bytes()
        assert data.index(b"moov") < data.index(b"mdat")  # faststart: playable while downloading
    names = sorted(p.name for p in result.stills)
    assert names == ["insertion.png", "signals.png", "signals.svg", "stress_insertion.exr"]
    assert not list(tmp_path.glob("*.partial*"))


def test_bad_settings_are_named():
    with pytest.raises(MetricsError, match="even"):
        ReplaySettings(size=(321, 180))
    with pytest.raises(MetricsError, match="mode"):
        ReplaySettings(mode="mirror")


def test_side_by_side_needs_an_expert(recorded, tmp_path):
    tissue, trainee, _ = recorded
    with pytest.raises(MetricsError, match="needs an expert"):
        export_replay(trainee, tissue, tmp_path / "x.mp4", [], ReplaySettings(mode="side-by-side"))
    assert not list(tmp_path.iterdir())


def test_stress_map_known_answer_and_exr_round_trip(tmp_path):
    import OpenImageIO as oiio

    from metrics.replay.stills import write_stress_map

    # a 1 mm square in the z = 0 plane as two triangles, facing +z, with 1 kPa and 3 kPa
    points = np.array([[0, 0, 0], [1e-3, 0, 0], [1e-3, 1e-3, 0], [0, 1e-3, 0]], dtype=float)
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    image, u, v = stress_map(points, triangles, np.array([1e3, 3e3]), np.array([0.0, 0.0, 1.0]), pixel=1e-4)
    assert image.shape == (11, 11)
    np.testing.assert_allclose(u, [1, 0, 0]) and np.testing.assert_allclose(v, [0, 1, 0])
    # row 0 is the top (largest v): below the diagonal (x > y) is triangle 0, above it triangle 1
    assert image[8, 7] == 1e3 and image[2, 2] == 3e3  # (x, y) = (0.7, 0.2) mm and (0.2, 0.8) mm
    path = write_stress_map(tmp_path / "map.exr", image)
    back = oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[:, :, 0]
    np.testing.assert_array_equal(back, image)


@pytest.mark.slow
def test_blind_render_shows_the_session_alone_in_every_frame(recorded, tmp_path):
    """Issue 44, seen 6: every decoded frame of the blind render carries the blind strip and key and
    no ghost green, stress orange or judging bite colour; the supervisor's replay of the same session
    fails the same reading (so the reading can fail); the file names no participant."""
    from tests.blind_video import blind_problems, decoded_frames

    tissue, trainee, experts = recorded
    settings = ReplaySettings(fps=15, size=(320, 180), blind=True)
    blind = export_replay(trainee, tissue, tmp_path / "blind.mp4", [], settings)
    frames = decoded_frames(blind.path)
    assert len(frames) == blind.frames > 10
    assert blind_problems(frames, marks=False, wound=False) == []
    assert b"T01" not in blind.path.read_bytes() and b"trainee" not in blind.path.read_bytes()
    shown = export_replay(
        trainee, tissue, tmp_path / "open.mp4", experts, ReplaySettings(fps=15, size=(320, 180))
    )
    problems = blind_problems(decoded_frames(shown.path), marks=False, wound=False)
    assert any("strip differs" in p for p in problems) and any("key differs" in p for p in problems)
    assert any("green pixels" in p for p in problems) and any("orange pixels" in p for p in problems)
    with pytest.raises(MetricsError, match="session alone"):
        export_replay(trainee, tissue, tmp_path / "x.mp4", experts, settings)
    with pytest.raises(MetricsError, match="side by side"):
        ReplaySettings(blind=True, mode="side-by-side")
