"""The replay frame's layout (issue 25): readouts and key beside the tissue, never over it, readable when a
1280 x 720 video plays 530 px wide; the wound's cut-face rim found in the mesh."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from metrics.replay.export import replay_keys
from metrics.replay.hud import TEXT, WIDEST_LINES, FrameLayout, _rows, _thickness, draw_key
from metrics.replay.wound import outline_edges, wound_nodes
from sim.mesh import Wound, vessel_mesh
from sim.render import stress_colours


@pytest.mark.parametrize("views", [1, 2])
def test_every_readout_fits_its_strip_and_the_key_is_beside_the_views(views):
    readouts = [("expert E02  t = 888.88 s", list(WIDEST_LINES)), ("t = 1.00 s", list(WIDEST_LINES[:2]))]
    layout = FrameLayout.of((1280, 720), views, readouts)
    width, height = layout.view_size
    assert views * width + layout.panel <= 1280 and height + layout.strip == 720
    rows = _rows(*readouts[0], width, layout.scale)
    assert len(rows) * 38 * layout.scale <= layout.strip  # the widest readout fits the strip
    for row in rows:
        x, pieces = row[-1]
        assert x < width  # wrapped, not cut
    # compose: the strip's dark band on top, the view's pixels below it, the key on the right
    view = np.full((height, width, 3), 7, dtype=np.uint8)
    key = np.full((720, layout.panel, 3), 250, dtype=np.uint8)
    frame = layout.compose([(view, "t = 1.00 s", list(WIDEST_LINES))] * views, key)
    assert (frame[layout.strip :, : views * width] == 7).all()
    assert (frame[:, 1280 - layout.panel :] == 250).all()


def test_values_are_at_least_8_px_tall_when_a_720p_video_plays_530_px_wide():
    scale = 720 / 720
    (_, digits), _ = cv2.getTextSize("0123456789", cv2.FONT_HERSHEY_SIMPLEX, TEXT * scale, _thickness(scale))
    assert digits * 530 / 1280 >= 8


def test_the_key_fits_its_panel_with_every_entry():
    layout = FrameLayout.of((1280, 720), 1)
    keys = replay_keys(ghost=True, marks=True, wound=True)
    assert [k.text for k in keys][-1] == "wound edge" and len(keys) == 8
    panel = draw_key(720, layout.panel, layout.scale, (0.0, 500.0), stress_colours(), keys)
    ink = np.flatnonzero((panel < 128).any(axis=2).any(axis=1))
    assert ink.max() < 720 - 10  # the last entry drawn above the bottom edge, none cut off


def test_a_two_handed_session_s_key_names_the_forceps_in_the_colours_drawn_and_still_fits():
    from metrics.replay.blind import blind_keys
    from sim.render import FORCEPS_CLOSED_COLOUR, FORCEPS_OPEN_COLOUR

    layout = FrameLayout.of((1280, 720), 1)
    keys = replay_keys(ghost=True, marks=True, wound=True, forceps=True)
    assert [k.text for k in keys][-2:] == ["forceps, open", "forceps, closed"] and len(keys) == 10
    drawn = [np.array(k.colours[0]) / 255 for k in keys[-2:]]
    np.testing.assert_allclose(drawn, [FORCEPS_OPEN_COLOUR, FORCEPS_CLOSED_COLOUR], atol=0.5 / 255)
    assert [k.text for k in blind_keys(True, True, forceps=True)][-2:] == ["forceps, open", "forceps, closed"]
    assert "forceps, open" not in [k.text for k in blind_keys(True, True)]  # one-handed: no forceps
    panel = draw_key(720, layout.panel, layout.scale, (0.0, 500.0), stress_colours(), keys)
    ink = np.flatnonzero((panel < 128).any(axis=2).any(axis=1))
    assert ink.max() < 720 - 10


def test_a_cut_face_outline_is_its_rim():
    # two triangles making the unit square (nodes 0-3), one more off the face (node 4)
    triangles = np.array([[0, 1, 2], [0, 2, 3], [2, 3, 4]])
    edges = outline_edges(triangles, np.array([0, 1, 2, 3]))
    assert {tuple(e) for e in edges} == {(0, 1), (1, 2), (2, 3), (0, 3)}  # not the diagonal (0, 2)
    assert outline_edges(triangles, np.array([0, 1])).shape == (0, 2)


def test_a_cut_vessels_wound_is_its_two_incision_faces():
    mesh = vessel_mesh(
        length=10e-3, arc_deg=90.0, circumferential_divisions=16, radial_divisions=2, axial_divisions=10,
        wound=Wound(angle_deg=0.0, z_start=2e-3, z_end=8e-3, gap=1.5e-4),
    )  # fmt: skip
    nodes = wound_nodes(mesh)
    assert set(nodes) == set(mesh.node_sets["wound_a"]) | set(mesh.node_sets["wound_b"])
    rim = outline_edges(mesh.surface_triangles, nodes)
    assert len(rim) > 0 and np.isin(rim, nodes).all()
    # a block's free edge: the surface in the wound plane
    assert wound_nodes(mesh, None, None).size == nodes.size
