"""The PyVista scene: tissue with a von Mises colour map, the needle, the contact point, a ghost path.

On screen where a display exists, offscreen through EGL otherwise. VTK and
PyVista are imported only when a renderer is made, so the core imports without
them. After moving points in place the meshes are marked modified and rendered
before pixels are read, otherwise frames silently repeat.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.errors import VascsimError
from sim.mesh import TetMesh

STRESS_RANGE_PA = (0.0, 5e5)
"""The colour scale's range: 0-500 kPa holds a calibrated arterial wall's stitch (puncture about 0.15 MPa
near the needle, levering several times that); shown in kPa."""
FORCE_ARROW_M_PER_N = 0.003
"""Force arrows are 3 mm long per newton: an expert's 0.8 N puncture 2.4 mm, a fifth of the 12 mm
patch; a levered 2 N, 6 mm, still inside the view."""


def vtk_matrix():
    from vtkmodules.vtkCommonMath import vtkMatrix4x4

    return vtkMatrix4x4()


class RenderError(VascsimError):
    """The scene could not be rendered or written."""


@dataclass(frozen=True)
class RenderFrame:
    """What one frame shows.

    points: (N, 3) current node positions of the mesh (m).
    triangle_stress: (F,) von Mises stress (Pa) of the element under each exterior triangle.
    needle: (S+1, 3) needle vertices, tip first; contact: insertion/contact point or None;
    ghost: (P, 3) path to draw as a ghost (e.g. the expert's needle-tip path) or None.
    force: (3,) reaction force on the needle (N), drawn as an arrow at the tip, or None.
    ghost_needle: (S+1, 3) a second needle drawn translucent (e.g. the expert's, aligned) or None.
    forceps: the subordinate hand's jaws, (jaw point (3,) m, closed), or None for a one-handed scene.
    """

    points: NDArray[np.float64]
    triangle_stress: NDArray[np.float64]
    needle: NDArray[np.float64]
    contact: NDArray[np.float64] | None = None
    ghost: NDArray[np.float64] | None = None
    force: NDArray[np.float64] | None = None
    ghost_needle: NDArray[np.float64] | None = None
    forceps: tuple[NDArray[np.float64], bool] | None = None


FORCEPS_SHOWN_LENGTH = 0.008
"""How much of the forceps' jaws a scene draws (m) from their tips."""
FORCEPS_OPEN_GAP = 0.0015
"""The open jaws' tips apart (m), as wide as the jaws' tips (:class:`sim.forceps.Forceps`)."""
FORCEPS_OPEN_COLOUR, FORCEPS_CLOSED_COLOUR = (0.56, 0.58, 0.6), (0.1, 0.1, 0.12)
"""Steel grey open, near black closed: colourless, so that neither they nor the video codec's colour
fringes along them read as the experts' green or the stress map's orange (a blinded replay is checked
for both: dark indigo jaws left a few orange pixels after H.264's chroma subsampling)."""


def forceps_points(
    jaw_point: NDArray[np.float64], closed: bool, towards_viewer: NDArray[np.float64], up: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(4, 3) ends of the forceps' two jaws as a scene draws them: tips at ``jaw_point`` (touching when
    ``closed``, :data:`FORCEPS_OPEN_GAP` apart when open), shafts rising towards the viewer and down
    the view (the hand is below and in front of the screen), spread across it."""
    point = np.asarray(jaw_point, dtype=np.float64)
    out = np.asarray(towards_viewer, dtype=np.float64)
    out = out / np.linalg.norm(out)
    up = np.asarray(up, dtype=np.float64)
    side = np.cross(out, up)
    length = float(np.linalg.norm(side))
    side = side / length if length > 0 else np.array([1.0, 0.0, 0.0])
    tip = (0.05e-3 if closed else 0.5 * FORCEPS_OPEN_GAP) * side
    back = point + FORCEPS_SHOWN_LENGTH * (out - 0.5 * up)
    spread = FORCEPS_OPEN_GAP * side
    return np.array([point + tip, back + spread, point - tip, back - spread])


def stress_colours():
    """The wall's colour scale: tissue pink at rest, through orange and red to dark red at the top of
    the stress range, so an unloaded wall looks like tissue (a dark-to-bright scale such as inferno
    paints it black) and the headlight's shading shows its shape."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list(
        "tissue-stress",
        [
            (0.0, (0.93, 0.74, 0.70)),
            (0.35, (0.96, 0.55, 0.33)),
            (0.7, (0.82, 0.16, 0.12)),
            (1.0, (0.40, 0.02, 0.08)),
        ],
    )


class TissueRenderer:
    """Renders :class:`RenderFrame` objects of one mesh to RGB arrays (H, W, 3) uint8."""

    def __init__(
        self,
        mesh: TetMesh,
        size: tuple[int, int] = (640, 480),
        offscreen: bool = True,
        stress_range: tuple[float, float] = STRESS_RANGE_PA,
        anti_aliasing: bool = True,
        scalar_bar: bool = True,
        force_scale: float = FORCE_ARROW_M_PER_N,
        zoom: float = 1.0,
        title: str = "vascsim",
    ) -> None:
        # the render window's class is VTK's choice (VTK_DEFAULT_OPENGL_WINDOW, which the application
        # sets without a display: sessions.config.prepare_rendering); VTK 9.7 falls back to EGL itself
        import pyvista as pv

        self._pv = pv
        self.mesh = mesh
        faces = np.hstack([np.full((len(mesh.surface_triangles), 1), 3), mesh.surface_triangles]).ravel()
        self.surface = pv.PolyData(mesh.points.copy(), faces)
        self.surface.cell_data["von Mises (kPa)"] = np.zeros(len(mesh.surface_triangles))
        self.size = size
        self.stress_range = stress_range
        self.force_scale = force_scale
        self.zoom = zoom
        # one headlight (a light at the camera, as VTK's own default): under software rasterisation
        # every light is paid per pixel, and PyVista's five-light kit doubled a full frame's cost
        self.plotter = pv.Plotter(off_screen=offscreen, window_size=size, lighting="none", title=title)
        self.plotter.add_light(pv.Light(light_type="headlight"))
        if not anti_aliasing:  # 4x MSAA costs ~3x the frame time under software rendering
            self.plotter.disable_anti_aliasing()
        self.plotter.set_background("white")
        self._surface_actor = self.plotter.add_mesh(
            self.surface,
            scalars="von Mises (kPa)",
            cmap=stress_colours(),
            clim=(stress_range[0] / 1e3, stress_range[1] / 1e3),  # shown in kPa
            show_edges=False,
            smooth_shading=False,
            show_scalar_bar=scalar_bar,
            scalar_bar_args={
                "title": "stress\n(kPa)",
                "color": "black",
                "fmt": "%.3g",
                "vertical": True,
                "position_x": 0.84,
                "position_y": 0.1,
                "width": 0.1,
                "height": 0.8,
            },
        )
        # the tissue surface is closed and outward-oriented: its back faces are never seen, and not
        # shading them cut a 10k-node artery's frame time by a third under software rendering
        self._surface_actor.GetProperty().BackfaceCullingOn()
        self.needle = pv.PolyData(np.zeros((2, 3)), lines=np.array([2, 0, 1]))
        self.plotter.add_mesh(self.needle, color="silver", line_width=5, render_lines_as_tubes=True)
        self.marker = pv.PolyData(np.zeros((1, 3)))
        self._marker_actor = self.plotter.add_mesh(
            self.marker, color="deepskyblue", point_size=14, render_points_as_spheres=True
        )
        self.ghost = pv.PolyData(np.zeros((2, 3)), lines=np.array([2, 0, 1]))
        # ghosts are opaque: any translucent actor makes VTK add order-independent-transparency passes
        # over the whole frame, which cost a 10k-node artery's frame 12 ms under software rendering
        self._ghost_actor = self.plotter.add_mesh(self.ghost, color="limegreen", line_width=3)
        self.ghost_needle = pv.PolyData(np.zeros((2, 3)), lines=np.array([2, 0, 1]))
        self._ghost_needle_actor = self.plotter.add_mesh(
            self.ghost_needle, color="mediumseagreen", line_width=4
        )
        self.forceps = pv.PolyData(np.zeros((4, 3)), lines=np.array([2, 0, 1, 2, 2, 3]))
        self._forceps_actor = self.plotter.add_mesh(self.forceps, color=FORCEPS_OPEN_COLOUR, line_width=7)
        self._forceps_actor.SetVisibility(False)
        # a unit arrow along +x, placed each frame by a user matrix (no new geometry per frame)
        self._arrow_actor = self.plotter.add_mesh(
            pv.Arrow(
                start=(0.0, 0.0, 0.0),
                direction=(1.0, 0.0, 0.0),
                tip_length=0.3,
                tip_radius=0.12,
                shaft_radius=0.04,
            ),
            color="dodgerblue",
        )
        # the task's target marks and where bites went (show_placement), bites revealed as they happen
        self._bites = np.zeros((0, 3))
        self._bite_colours = np.zeros((0, 3), dtype=np.uint8)
        self._bite_actor = None
        self._bites_shown = 0
        self._outline = None  # show_outline: edges drawn along mesh nodes, moved with the tissue
        self._outline_nodes = np.zeros(0, dtype=np.int64)
        self._arrow_matrix = vtk_matrix()
        self._arrow_actor.SetUserMatrix(self._arrow_matrix)
        self._pixels = None
        self._camera_set = False

    def show_placement(self, targets: NDArray[np.float64], bites: NDArray[np.float64], colours) -> None:
        """The task's target marks (m, drawn as small white dots) and where bites went (m, one RGB
        colour each, uint8), the bites revealed one by one with :meth:`reveal_bites`."""
        marks = self._pv.PolyData(np.asarray(targets, dtype=np.float64).reshape(-1, 3))
        self.plotter.add_mesh(marks, color="white", point_size=8, render_points_as_spheres=True)
        self._bites = np.asarray(bites, dtype=np.float64).reshape(-1, 3)
        self._bite_colours = np.asarray(colours, dtype=np.uint8).reshape(-1, 3)

    def show_outline(self, edges: NDArray[np.int64], colour: str = "#6b0a1a", width: float = 4.0) -> None:
        """Draw ``edges`` ((E, 2) mesh node ids, e.g. the wound's cut face rim) as lines that move with
        the tissue in every later frame."""
        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        if not len(edges):
            return
        nodes, local = np.unique(edges, return_inverse=True)
        lines = np.hstack([np.full((len(edges), 1), 2), local.reshape(-1, 2)]).ravel()
        self._outline = self._pv.PolyData(self.mesh.points[nodes].copy(), lines=lines)
        self._outline_nodes = nodes
        self.plotter.add_mesh(self._outline, color=colour, line_width=width, render_lines_as_tubes=True)

    def reveal_bites(self, count: int) -> None:
        """Show the first ``count`` bite marks (a replay shows each once it has been made)."""
        count = min(count, len(self._bites))
        if count == self._bites_shown:
            return
        if self._bite_actor is not None:
            self.plotter.remove_actor(self._bite_actor)
            self._bite_actor = None
        if count > 0:
            points = self._pv.PolyData(self._bites[:count])
            points.point_data["colour"] = self._bite_colours[:count]
            self._bite_actor = self.plotter.add_mesh(
                points,
                scalars="colour",
                rgb=True,
                point_size=11,
                render_points_as_spheres=True,
                show_scalar_bar=False,
            )
        self._bites_shown = count

    def set_camera(self, position, focal_point, view_up) -> None:
        """Fix the camera (m): replays use one camera for every frame, and for both sides of a comparison."""
        self.plotter.camera_position = [tuple(position), tuple(focal_point), tuple(view_up)]
        self._camera_set = True

    def share_camera(self, other: TissueRenderer) -> None:
        """Use ``other``'s camera as it is now (position, focus, view angle) for every later frame:
        the two sides of a comparison seen alike."""
        self.plotter.renderer.GetActiveCamera().DeepCopy(other.plotter.renderer.GetActiveCamera())
        self._camera_set = True

    def render(self, frame: RenderFrame) -> NDArray[np.uint8]:
        """Draw a frame and return its pixels."""
        self.update(frame)
        return self.read_pixels()

    def update(self, frame: RenderFrame) -> None:
        """Put a frame into the scene without drawing it (a window draws it with its own render call)."""
        self.surface.points[:] = frame.points
        self.surface.cell_data["von Mises (kPa)"][:] = frame.triangle_stress / 1e3
        self.surface.Modified()
        if self._outline is not None:
            self._outline.points[:] = frame.points[self._outline_nodes]
            self._outline.Modified()
        _set_polyline(self.needle, frame.needle)
        self._marker_actor.SetVisibility(frame.contact is not None)
        if frame.contact is not None:
            self.marker.points[:] = frame.contact
            self.marker.Modified()
        self._ghost_actor.SetVisibility(frame.ghost is not None and len(frame.ghost) > 1)
        if frame.ghost is not None and len(frame.ghost) > 1:
            _set_polyline(self.ghost, frame.ghost)
        self._ghost_needle_actor.SetVisibility(frame.ghost_needle is not None)
        if frame.ghost_needle is not None:
            _set_polyline(self.ghost_needle, frame.ghost_needle)
        self._place_arrow(frame)
        if not self._camera_set:
            self.plotter.camera_position = "iso"
            self.plotter.reset_camera()
            self.plotter.renderer.GetActiveCamera().Zoom(self.zoom)
            self._camera_set = True
        self.place_forceps(frame.forceps)

    def place_forceps(self, jaws: tuple[NDArray[np.float64], bool] | None) -> None:
        """Draw the subordinate hand's jaws (:func:`forceps_points`, grey open, near black closed) as the
        camera sees them now; hide them for None."""
        self._forceps_actor.SetVisibility(jaws is not None)
        if jaws is None:
            return
        camera = self.plotter.renderer.GetActiveCamera()
        towards = np.subtract(camera.GetPosition(), camera.GetFocalPoint())
        self.forceps.points[:] = forceps_points(jaws[0], bool(jaws[1]), towards, np.array(camera.GetViewUp()))
        self.forceps.Modified()
        colour = FORCEPS_CLOSED_COLOUR if jaws[1] else FORCEPS_OPEN_COLOUR
        self._forceps_actor.GetProperty().SetColor(*colour)

    def read_pixels(self) -> NDArray[np.uint8]:
        """Render and read the frame straight from the render window: (H, W, 3) uint8, top row first."""
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkCommonCore import vtkUnsignedCharArray

        window = self.plotter.render_window
        window.Render()
        if self._pixels is None:
            self._pixels = vtkUnsignedCharArray()
        width, height = window.GetSize()
        window.GetPixelData(0, 0, width - 1, height - 1, 1, self._pixels, 0)
        return vtk_to_numpy(self._pixels).reshape(height, width, 3)[::-1].copy()

    def _place_arrow(self, frame: RenderFrame) -> None:
        force = frame.force
        magnitude = 0.0 if force is None else float(np.linalg.norm(force))
        self._arrow_actor.SetVisibility(magnitude > 1e-6)
        if magnitude <= 1e-6:
            return
        length = magnitude * self.force_scale
        x = np.asarray(force, dtype=np.float64) / magnitude
        helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        y = np.cross(helper, x)
        y /= np.linalg.norm(y)
        z = np.cross(x, y)
        transform = np.eye(4)
        transform[:3, 0], transform[:3, 1], transform[:3, 2] = x * length, y * length, z * length
        transform[:3, 3] = frame.needle[0]
        for row in range(4):
            for column in range(4):
                self._arrow_matrix.SetElement(row, column, float(transform[row, column]))
        self._arrow_matrix.Modified()

    def close(self) -> None:
        self.plotter.close()


def _set_polyline(poly, vertices: NDArray[np.float64]) -> None:
    n = len(vertices)
    if poly.n_points != n:
        poly.points = vertices.copy()
        poly.lines = np.concatenate([[n], np.arange(n)])
    else:
        poly.points[:] = vertices
    poly.Modified()


def surface_stress(mesh: TetMesh, von_mises: NDArray[np.float64]) -> NDArray[np.float64]:
    """(F,) stress of the element each exterior triangle belongs to."""
    return von_mises[mesh.surface_elements]


def write_image(path: str | Path, pixels: NDArray, float_data: NDArray[np.float32] | None = None) -> Path:
    """Write an image through OpenImageIO: PNG/JPEG from uint8 pixels, or EXR from float data."""
    import OpenImageIO as oiio

    path = Path(path)
    data = pixels if float_data is None else float_data
    data = np.ascontiguousarray(data)
    if data.ndim == 2:
        data = data[:, :, None]
    height, width, channels = data.shape
    fmt = oiio.UINT8 if data.dtype == np.uint8 else oiio.FLOAT
    output = oiio.ImageOutput.create(str(path))
    if output is None:
        raise RenderError(f"cannot write {path}: {oiio.geterror()}")
    if not output.open(str(path), oiio.ImageSpec(width, height, channels, fmt)):
        raise RenderError(f"cannot write {path}: {output.geterror()}")
    ok = output.write_image(data)
    output.close()
    if not ok:
        raise RenderError(f"writing {path} failed: {output.geterror()}")
    return path


def compare_images(
    path_a: str | Path, path_b: str | Path, fail_threshold: float = 0.1, warn_threshold: float = 0.02
) -> tuple[int, float, float]:
    """OpenImageIO's compare: (number of pixels over the fail threshold, mean error, max error)."""
    import OpenImageIO as oiio

    a, b = oiio.ImageBuf(str(path_a)), oiio.ImageBuf(str(path_b))
    if a.has_error or b.has_error:
        raise RenderError(f"cannot read images for comparison: {a.geterror()} {b.geterror()}")
    result = oiio.ImageBufAlgo.compare(a, b, fail_threshold, warn_threshold)
    return int(result.nfail), float(result.meanerror), float(result.maxerror)


def read_image(path: str | Path) -> NDArray[np.uint8]:
    """An image file's pixels through OpenImageIO: (H, W, C) uint8."""
    import OpenImageIO as oiio

    buffer = oiio.ImageBuf(str(path))
    if buffer.has_error:
        raise RenderError(f"cannot read {path}: {buffer.geterror()}")
    return buffer.get_pixels(oiio.UINT8)
