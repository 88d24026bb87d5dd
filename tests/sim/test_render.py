"""Offscreen rendering through VTK/EGL, compared with a reference image by OpenImageIO."""

import os
from pathlib import Path

import numpy as np
import pytest

from sim.calibration.indentation import paper_cube, top_contact_triangle
from sim.fem import Material, TissueModel
from sim.needle import Needle, Pose, rotation_aligning
from sim.render import RenderFrame, TissueRenderer, compare_images, surface_stress, write_image

GOLDEN = Path(__file__).parents[1] / "data" / "golden" / "cube_press.png"


def pressed_cube_frame():
    mesh, fixed = paper_cube()
    model = TissueModel(mesh, Material(20e3, 0.45), fixed)
    model.precompute(use_cache=False)
    triangle = top_contact_triangle(mesh)
    weights = np.array([0.5, 0.3, 0.2])
    press = np.array([0.0, 0.0, -0.002])
    solution = model.solve({int(n): w * press for n, w in zip(triangle, weights, strict=True)}, fields=True)
    needle = Needle.curved()
    contact = weights @ mesh.points[triangle] + press
    rotation = rotation_aligning(needle.tip_direction, [0, 0, -1])
    pose = Pose(contact - rotation @ needle.vertices[0], rotation)
    ghost = np.array([[0.0, 0.0, 0.012], [0.005, 0.005, 0.011], [0.01, 0.01, 0.012]])
    frame = RenderFrame(
        mesh.points + solution.displacement,
        surface_stress(mesh, solution.von_mises),
        needle.world_vertices(pose),
        contact,
        ghost,
    )
    return mesh, frame


def test_render_matches_the_reference_image(tmp_path):
    mesh, frame = pressed_cube_frame()
    # the paper's 20 kPa cube: a colour scale of 0-5 kPa (the calibrated wall's default is 0-500 kPa)
    renderer = TissueRenderer(mesh, size=(320, 240), offscreen=True, stress_range=(0.0, 5e3))
    pixels = renderer.render(frame)
    renderer.close()
    assert pixels.shape == (240, 320, 3) and pixels.dtype == np.uint8
    out = write_image(tmp_path / "cube_press.png", pixels)
    if os.environ.get("VASCSIM_UPDATE_GOLDEN"):
        write_image(GOLDEN, pixels)
    failed, mean_error, _ = compare_images(out, GOLDEN, fail_threshold=0.1)
    assert failed <= 0.005 * pixels.shape[0] * pixels.shape[1], (failed, mean_error)
    assert mean_error < 0.01


def test_frames_change_when_points_move(tmp_path):
    """Moving points in place must produce a new frame, not a silently repeated one."""
    mesh, frame = pressed_cube_frame()
    renderer = TissueRenderer(mesh, size=(160, 120), offscreen=True)
    first = renderer.render(frame).copy()
    moved = RenderFrame(frame.points + np.array([0.0, 0.0, 0.003]), frame.triangle_stress * 0.2, frame.needle)
    second = renderer.render(moved)
    renderer.close()
    assert np.abs(first.astype(int) - second.astype(int)).mean() > 1.0


def test_exr_and_compare(tmp_path):
    stress = np.linspace(0, 1, 64 * 32, dtype=np.float32).reshape(32, 64)
    exr = write_image(tmp_path / "stress.exr", None, float_data=stress)
    assert compare_images(exr, exr) == (0, 0.0, 0.0)
    import OpenImageIO as oiio

    back = oiio.ImageBuf(str(exr)).get_pixels(oiio.FLOAT)
    np.testing.assert_allclose(back[:, :, 0], stress)
    with pytest.raises(Exception, match="cannot"):
        write_image(tmp_path / "no_such_dir" / "x.png", np.zeros((2, 2, 3), np.uint8))


def test_the_display_scene_shows_the_solved_field_and_keeps_its_handle_per_contact_set():
    """The display layer's scene: a contact renders the tissue deformed as a full-field solve
    deforms it, from one whole-field handle per contact set (rebuilt when the set changes)."""
    from sim.runtime.display import DisplayScene
    from sim.runtime.snapshots import GraphicsSnapshot

    mesh, fixed = paper_cube()
    model = TissueModel(mesh, Material(20e3, 0.45), fixed)
    scene = DisplayScene(model, TissueRenderer(mesh, size=(160, 120), offscreen=True))
    needle = Needle.curved().world_vertices(Pose.identity())
    triangle = np.asarray(top_contact_triangle(mesh), dtype=np.int64)
    rendered = []
    real_render = scene.renderer.render
    scene.renderer.render = lambda frame: rendered.append(frame) or real_render(frame)
    scene(GraphicsSnapshot(0.0, needle, "free", None, None))
    at_rest = scene.last_image
    push = np.array([[0.0, 0.0, -0.002]] * 3)
    scene(GraphicsSnapshot(0.1, needle, "contact", None, (triangle, push)))
    handle = scene._field
    scene(GraphicsSnapshot(0.2, needle, "contact", None, (triangle, 0.5 * push)))
    assert scene._field is handle  # the same contact set: no new solve
    solved = model.solve({int(n): a for n, a in zip(triangle, 0.5 * push, strict=True)}, full_field=True)
    np.testing.assert_allclose(rendered[-1].points, mesh.points + solved.displacement, atol=1e-12)
    expected_stress = model.surface_von_mises(solved.displacement)
    np.testing.assert_allclose(rendered[-1].triangle_stress, expected_stress, rtol=1e-9, atol=1e-9)
    assert expected_stress.max() > 10.0  # Pa: the push loads the surface
    upward = mesh.surface_triangles[mesh.surface_normals[:, 2] > 0.99]
    other = next(t for t in upward if not set(t.tolist()) & set(triangle.tolist())).astype(np.int64)
    scene(GraphicsSnapshot(0.3, needle, "contact", None, (other, push)))
    assert scene._field is not handle and scene._field.nodes.tolist() == other.tolist()
    assert scene.frames == 4 and np.abs(scene.last_image.astype(int) - at_rest).max() > 0


def test_bite_marks_appear_as_they_are_made_in_their_colour():
    """Issue 22: the task's marks drawn white, each bite in its error colour once revealed."""
    mesh, frame = pressed_cube_frame()
    renderer = TissueRenderer(mesh, size=(200, 150), offscreen=True)
    top = mesh.points[mesh.points[:, 2] > mesh.points[:, 2].max() - 1e-9]
    mark, bite = top[len(top) // 2], top[len(top) // 2 + 2]
    red = (210, 30, 30)
    renderer.show_placement(mark[None], bite[None], [red])

    def reds(pixels):
        return int(np.sum((pixels[..., 0] > 180) & (pixels[..., 1] < 70) & (pixels[..., 2] < 70)))

    def whites(pixels):
        return int(np.sum(np.all(pixels > 235, axis=2)))

    before = renderer.render(frame).copy()
    renderer.reveal_bites(1)
    after = renderer.render(frame).copy()
    renderer.reveal_bites(0)
    hidden = renderer.render(frame)
    renderer.close()
    # (the stress colour bar has a few such pixels of its own)
    assert reds(after) > reds(before) + 10 and reds(hidden) == reds(before)
    assert whites(before) > 0  # the mark (and the white background) are there from the start


def test_the_forceps_are_drawn_at_their_jaws_grey_open_and_black_closed():
    """A frame with the subordinate hand's jaws draws two jaws meeting at the jaw point: grey while
    open, near black once closed; a one-handed frame draws none."""
    from dataclasses import replace

    from sim.render import FORCEPS_CLOSED_COLOUR, FORCEPS_OPEN_COLOUR, forceps_points

    mesh, frame = pressed_cube_frame()
    renderer = TissueRenderer(mesh, size=(320, 240), offscreen=True, stress_range=(0.0, 5e3))
    jaw = np.array([*mesh.points[:, :2].mean(axis=0), mesh.points[:, 2].max()])
    shown = {}
    for name, jaws in (("none", None), ("open", (jaw, False)), ("closed", (jaw, True))):
        shown[name] = renderer.render(replace(frame, forceps=jaws)).astype(int)
    renderer.close()

    def coloured(pixels, colour):
        target = np.array(colour) * 255
        return int((np.abs(pixels - target).max(axis=2) < 40).sum())

    for name, colour in (("open", FORCEPS_OPEN_COLOUR), ("closed", FORCEPS_CLOSED_COLOUR)):
        assert coloured(shown[name], colour) > 100 + coloured(shown["none"], colour), name
    # the jaws' tips touch when closed, are 1.5 mm apart when open; the shafts spread wider
    ends = forceps_points(np.zeros(3), False, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert np.linalg.norm(ends[0] - ends[2]) == pytest.approx(1.5e-3)
    closed = forceps_points(np.zeros(3), True, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert np.linalg.norm(closed[0] - closed[2]) == pytest.approx(0.1e-3)
    assert np.linalg.norm(closed[1] - closed[3]) > np.linalg.norm(closed[0] - closed[2])
