"""On-demand contact columns solved ahead of contact, in a process of their own.

A contact on nodes whose K0^-1 columns are not known needs a sparse solve (~20 ms
per node on a 10k-node mesh). scikit-sparse keeps the interpreter lock during a
CHOLMOD solve, so a solve in any thread of the simulation process stops the FEM and
graphics threads for its whole length. :class:`ColumnWorker` therefore forks a
process that inherits the parent's factorisation and solves there; the parent only
waits on a pipe (which releases the lock) and caches what comes back.
:class:`Prefetcher` asks it for the surface nodes near the needle tip, nearest
first, so a contact change rarely waits for a solve at all.
"""

from __future__ import annotations

import collections
import os
import signal
import threading

import numpy as np
from numpy.typing import NDArray

from sim.collision.mesh import CollisionMesh
from sim.errors import SolverError
from sim.fem import Tissue, TissueModel
from sim.geometry import circle_through
from sim.runtime.osrt import PR_SET_PDEATHSIG, libc_functions

AHEAD_NODES = 6
"""Surface nodes nearest the point the tip is heading for, solved right after that triangle's own."""
SOLVE_CHUNK = 3
"""Nodes solved together (one multi-right-hand-side solve): a triangle's."""
WORKER_NICENESS = 5
"""The column worker yields to the FEM and graphics layers (real-time threads) and shares the core
evenly with the display process (the same niceness): at niceness 10 the display lost the core to
the worker's solves and drew 17 frames/s on the on-demand artery, at 5 it draws 26.6, and the
contact-change latency stayed at 2 ms with no column solved on the spot."""


def arc_ahead(needle_vertices: NDArray[np.float64], reach: float, segments: int = 16) -> NDArray[np.float64]:
    """Where the tip goes if the needle keeps to its own curve: (segments + 1, 3) points (m) from the
    tip along ``reach`` (m) of arc. A curved needle turned by the wrist follows its circle (the circle
    through its tip, middle and swage vertices); a straight one its axis."""
    tip, middle, swage = needle_vertices[0], needle_vertices[len(needle_vertices) // 2], needle_vertices[-1]
    circle = circle_through(tip, middle, swage)
    if circle is None:
        return line_ahead(tip, tip - needle_vertices[1], reach)
    centre, radius = circle
    radial = (tip - centre) / radius
    normal = np.cross(middle - centre, tip - centre)
    # in the needle's plane, perpendicular to the radius at the tip, pointing away from the middle:
    # ((m x t) x t) . (t - m) = |m|^2 |t|^2 - (m . t)^2 >= 0 for m, t the radii to middle and tip
    forward = np.cross(normal, radial)
    forward /= np.linalg.norm(forward)
    angles = np.linspace(0.0, reach / radius, segments + 1)
    return centre + radius * (np.cos(angles)[:, None] * radial + np.sin(angles)[:, None] * forward)


def line_ahead(tip: NDArray[np.float64], direction: NDArray[np.float64], reach: float) -> NDArray[np.float64]:
    """(2, 3) points: the tip and ``reach`` (m) further along ``direction`` (e.g. its motion)."""
    length = float(np.linalg.norm(direction))
    if not length > 0:
        return tip[None].copy()
    return np.stack([tip, tip + reach * direction / length])


class ColumnWorker:
    """A forked process solving columns of ``model``'s K0^-1 with the factorisation it inherited.

    ``solve(nodes)`` returns the (3N, 3k) columns at the nodes' dofs, exactly what the model
    would solve itself; it is safe to call from several threads (one request at a time).
    """

    def __init__(self, model: TissueModel) -> None:
        import multiprocessing

        model.factorize()  # in this process: the child inherits it (factorising after fork deadlocks)
        self.model = model
        self._owner = os.getpid()
        self._lock = threading.Lock()
        context = multiprocessing.get_context("fork")
        self._pipe, child_end = context.Pipe()
        self._process = context.Process(
            target=_serve, args=(model, child_end, self._owner), name="vascsim-columns", daemon=True
        )
        self._process.start()
        child_end.close()

    def solve(self, nodes: NDArray[np.int64]) -> NDArray[np.float64]:
        ids = np.ascontiguousarray(nodes, dtype=np.int64)
        if os.getpid() != self._owner:  # a process forked later (the display) solves with its own copy
            return self.model.solve_columns(ids)
        with self._lock:
            try:
                self._pipe.send_bytes(ids.tobytes())
                answer = self._pipe.recv_bytes()
            except (EOFError, OSError) as error:
                status = self._process.exitcode
                raise SolverError(
                    f"the column worker process stopped (exit code {status}); columns of nodes "
                    f"{ids.tolist()} were not solved"
                ) from error
        if answer[:1] != b"O":  # "O" + columns, or "E" + the worker's error
            message = answer[1:].decode(errors="replace")
            raise SolverError(f"the column worker could not solve nodes {ids.tolist()}: {message}")
        rows = 3 * self.model.mesh.n_nodes
        return np.frombuffer(answer, dtype=np.float64, offset=1).reshape(3 * len(ids), rows).T

    def close(self) -> None:
        with self._lock:
            try:
                self._pipe.send_bytes(b"")
            except OSError:
                pass
            self._pipe.close()
        self._process.join(timeout=5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()


def _serve(model: TissueModel, pipe, parent: int) -> None:
    """The worker's loop: node ids in, columns out (row-major (3k, 3N) float64); empty request = stop."""
    from threadpoolctl import threadpool_limits

    _end_with(parent)

    # Ctrl-C in the terminal reaches the whole process group: the run stops itself and then this
    # worker (an empty request), so the worker leaves the signal to its parent instead of dying with
    # a KeyboardInterrupt traceback of its own
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(WORKER_NICENESS)
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    if len(cores) > 1:  # off the last core, which the real-time haptic process takes
        os.sched_setaffinity(0, set(cores[:-1]))
    with threadpool_limits(1):
        while True:
            try:
                request = pipe.recv_bytes()
            except (EOFError, OSError):
                return
            if not request:
                return
            nodes = np.frombuffer(request, dtype=np.int64)
            try:
                columns = model.solve_columns(nodes)
            except Exception as error:  # sent back and raised in the parent, with the nodes named
                pipe.send_bytes(b"E" + f"{type(error).__name__}: {error}".encode())
                continue
            pipe.send_bytes(b"O" + np.ascontiguousarray(columns.T).tobytes())


def _end_with(parent: int) -> None:
    """Die when ``parent`` dies, killed included (Linux: PR_SET_PDEATHSIG). Its pipe never reports the
    parent gone while a sibling (the haptic or display process) holds the parent's end, so an orphaned
    worker would otherwise wait for a request for ever."""

    libc = libc_functions()
    if libc is not None:
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:  # the parent died before the request was in place
        os._exit(0)


def _own_inverse_models(tissue: Tissue) -> list[TissueModel]:
    """The models that solve their own columns (a biphase stiff phase sharing the soft inverse does not)."""
    models = list(tissue.models)
    return [model for model in models if model.inverse_source is None]


class Prefetcher:
    """A background thread asking column workers for the nodes the needle approaches."""

    def __init__(
        self,
        tissue: Tissue,
        collision: CollisionMesh | None = None,
        full_columns: bool = False,
        load_radius: float = 0.0,
    ) -> None:
        """``full_columns``: cache whole K0^-1 columns also for precomputed candidates (the live
        local-stress operator reads them; the precomputed matrix holds only candidate rows).
        ``load_radius`` (m): a predicted crossing asks for every surface node this close to it (a
        force kernel's nodes), not only the nearest few."""
        self.models = _own_inverse_models(tissue)
        self.full_columns = full_columns
        self.load_radius = load_radius
        self.on_demand = full_columns or any(model.precomputation is None for model in self.models)
        self.workers = [ColumnWorker(model) for model in self.models]
        for model, worker in zip(self.models, self.workers, strict=True):
            model.column_solver = worker.solve
        self._depth_model = tissue.base
        mesh = tissue.mesh
        # an exit can be on any face (lumen, wound edge), not only on contact candidates
        self._nodes = mesh.surface_nodes
        self._points = mesh.points[self._nodes]
        self._triangles = mesh.surface_triangles
        self._collision = collision or CollisionMesh(mesh)
        self._pending: set[int] = set()  # queued, not served yet
        self._last_ahead: dict[str, list[int]] = {}  # per kind of prediction: what it last asked
        # Two queues, newest request first in each: where the tip is heading (the next contact,
        # the exit face) always before the sphere around it, however many frames the sphere
        # keeps growing while the worker is busy.
        self._ahead: collections.deque[list[int]] = collections.deque()
        self._near: collections.deque[list[int]] = collections.deque()
        self._queues_lock = threading.Lock()  # the graphics thread asks, the worker thread takes
        self._wake = threading.Event()
        self._closed = False
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name="vascsim-prefetch", daemon=True)
        self._thread.start()

    def near(self, point: NDArray[np.float64], radius: float) -> None:
        """Ask for the surface nodes within ``radius`` of ``point`` not requested yet, nearest first."""
        self._raise_if_failed()
        squared = np.einsum("ij,ij->i", self._points - point, self._points - point)
        close = np.flatnonzero(squared <= radius * radius)
        close = self._nodes[close[np.argsort(squared[close])]]
        # not queued already, and not cached (a column evicted from the model's cache is asked again)
        fresh = [int(n) for n in close if int(n) not in self._pending and self._needs_columns(int(n))]
        if fresh:
            self._request(self._near, fresh)  # the newest first: where the needle is now

    def ahead(self, path: NDArray[np.float64], crossings: int = 2, kind: str = "path") -> None:
        """Ask first for the nodes of the surface triangles a predicted tip path meets: ``path`` is
        (P, 3) points (m) from the tip along the way it is going (:func:`arc_ahead`,
        :func:`line_ahead`). The first ``crossings`` count (the next contact, then the exit face on
        the far side of the wall), each with the surface nodes nearest its crossing point. A
        prediction is asked again only when what it needs changes; ``kind`` names it, so that
        several kinds of prediction made every frame do not keep re-asking each other's nodes."""
        self._raise_if_failed()
        if len(path) < 2:
            return
        travelled = np.ascontiguousarray(path[::-1])  # the collision query wants the tip end first
        hits = self._collision.query(travelled)
        if len(hits) == 0:
            return
        along = len(path) - 2 - hits.segment  # path segment index, from the tip outwards
        order = np.lexsort((hits.t, along))[:crossings]
        points = hits.points(travelled[1:], travelled[:-1])[order]
        heading: list[int] = []
        for triangle, point in zip(hits.triangle[order], points, strict=True):
            squared = np.einsum("ij,ij->i", self._points - point, self._points - point)
            count = min(len(squared), max(AHEAD_NODES, int(np.count_nonzero(squared <= self.load_radius**2))))
            closest = np.argpartition(squared, count - 1)[:count]
            around = self._nodes[closest[np.argsort(squared[closest])]]
            heading += [*map(int, self._triangles[triangle]), *map(int, around)]
        # columns or depth missing, even if a sphere request already holds them further back
        waiting = [
            n
            for n in dict.fromkeys(heading)
            if self._needs_columns(n) or not self._depth_model.knows_depth(n)
        ]
        if waiting and waiting != self._last_ahead.get(kind):
            self._last_ahead[kind] = waiting
            self._request(self._ahead, waiting)  # before any sphere: this is where the next contact is

    @property
    def requests(self) -> list[list[int]]:
        """The node requests not served yet, in the order the worker will take them."""
        with self._queues_lock:
            return [*self._ahead, *self._near]

    def _request(self, queue: collections.deque[list[int]], nodes: list[int]) -> None:
        with self._queues_lock:
            self._pending.update(nodes)
            queue.appendleft(nodes)
        self._wake.set()

    def _next_chunk(self) -> list[int] | None:
        """The next nodes to solve: a triangle's worth from the front of the first queue that has any
        (the rest of that request stays at its front, so a newer request overtakes it)."""
        with self._queues_lock:
            for queue in (self._ahead, self._near):
                if queue:
                    batch = queue.popleft()
                    chunk, rest = batch[:SOLVE_CHUNK], batch[SOLVE_CHUNK:]
                    if rest:
                        queue.appendleft(rest)
                    return chunk
        return None

    def _needs_columns(self, node: int) -> bool:
        return any(model.needs_solve(node, self.full_columns) for model in self.models)

    def _raise_if_failed(self) -> None:
        """The worker thread's failure, raised in the asking (graphics) layer."""
        if self.error is not None:
            raise SolverError(f"column prefetching failed: {self.error}") from self.error

    def _work(self) -> None:
        try:
            while not self._closed:
                self._wake.wait(0.1)
                self._wake.clear()
                # a triangle at a time: newer requests overtake, and one solve of three nodes
                # costs 29 ms where three of one cost 53 (10k nodes)
                while not self._closed and (chunk := self._next_chunk()) is not None:
                    for model in self.models:
                        model.prefetch(np.array(chunk), full=self.full_columns)
                    # a contact needs their depth too (~0.1 ms a node at 10k nodes)
                    self._depth_model.cast_depths(chunk)
                    with self._queues_lock:
                        self._pending.difference_update(chunk)
        except BaseException as error:  # raised in the graphics layer at its next request
            self.error = error

    def close(self) -> None:
        self._closed = True
        self._wake.set()
        self._thread.join(timeout=10.0)
        for model, worker in zip(self.models, self.workers, strict=True):
            model.column_solver = None
            worker.close()


def needs_column_worker(tissue: Tissue) -> bool:
    """Whether some contact could need columns solved on demand (no precomputation, or free
    surface nodes outside the precomputed candidates, e.g. the lumen an exit goes through;
    nodes held fixed on all three axes are not worth a worker: the tissue is clamped there)."""
    models = tissue.models
    for model in models:
        if model.precomputation is None:
            return True
        free_surface = np.setdiff1d(tissue.mesh.surface_nodes, model.clamped_nodes)
        if len(np.setdiff1d(free_surface, model.contact_nodes)):
            return True
    return False
