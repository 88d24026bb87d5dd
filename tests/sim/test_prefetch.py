"""On-demand columns solved in a worker process: the same columns, errors that name the nodes, no
solve in the simulation process (where a CHOLMOD solve would hold the interpreter lock)."""

import os
import signal
import time

import numpy as np
import pytest

from sim.errors import SolverError
from sim.fem import BiphaseTissue, Material, TissueModel
from sim.mesh import box_mesh
from sim.needle.forces import NeedleForces
from sim.runtime.prefetch import ColumnWorker, Prefetcher, arc_ahead, line_ahead

# the real-time clock needs the machine to itself (scripts/test runs these after the rest)
pytestmark = pytest.mark.exclusive

PAPER = NeedleForces.paper()  # these tests drive the paper's soft tissue with its needle rule


@pytest.fixture
def model(small_box):
    return TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])


def test_the_worker_solves_exactly_the_columns_the_model_would(model):
    worker = ColumnWorker(model)
    try:
        nodes = np.array([5, 17, 3])
        np.testing.assert_array_equal(worker.solve(nodes), model.solve_columns(nodes))
    finally:
        worker.close()


def test_a_dead_worker_is_named_with_the_nodes_it_did_not_solve(model):
    worker = ColumnWorker(model)
    os.kill(worker._process.pid, signal.SIGKILL)
    worker._process.join()
    with pytest.raises(SolverError, match=r"column worker process stopped .*nodes \[4, 9\]"):
        worker.solve(np.array([4, 9]))
    worker.close()


def test_a_failing_solve_is_reported_not_swallowed(model):
    worker = ColumnWorker(model)
    try:
        with pytest.raises(SolverError, match=r"could not solve nodes \[100000\]: IndexError"):
            worker.solve(np.array([100000]))
        assert worker.solve(np.array([1])).shape == (3 * model.mesh.n_nodes, 3)  # still serving
    finally:
        worker.close()


def test_prefetched_columns_come_from_the_worker_process(small_box, monkeypatch):
    tissue = BiphaseTissue.build(small_box, small_box.node_sets["z0"])
    expected = {n: tissue.soft.solve_columns(np.array([n])) for n in (0, 1)}
    prefetcher = Prefetcher(tissue)
    assert prefetcher.models == [tissue.soft]  # the stiff phase shares the soft inverse: nothing to solve

    def not_here(nodes):
        raise AssertionError("a column was solved in the simulation process")

    monkeypatch.setattr(tissue.soft, "solve_columns", not_here)  # the forked worker kept the real one
    try:
        prefetcher.near(small_box.points[0], radius=1e-9)  # node 0 only
        prefetcher.near(small_box.points[1], radius=1e-9)
        deadline = time.monotonic() + 30
        while (
            tissue.soft.needs_solve(0, full=True) or tissue.soft.needs_solve(1, full=True)
        ) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert prefetcher.error is None
        np.testing.assert_array_equal(tissue.soft._nodes_columns(np.array([0])), expected[0])
        np.testing.assert_array_equal(tissue.stiff._nodes_columns(np.array([1])), expected[1] / 2.0)
    finally:
        prefetcher.close()
    assert tissue.soft.column_solver is None and not prefetcher.workers[0]._process.is_alive()


def test_the_triangle_the_tip_heads_for_is_solved_first(small_box):
    from sim.geometry import ray_triangle_distances

    tissue = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    top = small_box.points[:, 2].max()
    tip = np.array([0.0021, 0.0023, top + 0.002])
    down = np.array([0.0, 0.0, -1.0])
    corners = small_box.points[small_box.surface_triangles]
    expected = small_box.surface_triangles[np.argmin(ray_triangle_distances(tip, down, corners))]
    prefetcher = Prefetcher(tissue)
    try:
        prefetcher._closed = True  # keep the request queue as asked, unserved
        prefetcher._thread.join()
        prefetcher.near(tip, radius=0.01)  # a wide sphere first ...
        prefetcher.ahead(line_ahead(tip, down, reach=0.01))  # ... is overtaken by where the tip is going
        assert prefetcher.requests[0][:3] == [int(n) for n in expected]
        prefetcher.ahead(line_ahead(tip, -down, reach=0.01))  # heading away: nothing new
        prefetcher.ahead(line_ahead(tip, down, reach=0.001))  # out of reach: nothing new
        assert len(prefetcher.requests) == 2
    finally:
        prefetcher.close()


def straight_through(box):
    """An on-demand model of ``box``, a tip 1 mm above its top face and a straight path down
    through it and out of the bottom face: (tissue, tip, path)."""
    tissue = TissueModel(box, Material(20e3, 0.45), box.node_sets["x0"])
    low, high = box.points.min(axis=0), box.points.max(axis=0)
    tip = np.array([0.41, 0.43, 0.0]) * (high - low) + low + [0, 0, (high - low)[2] + 1e-3]
    return tissue, tip, line_ahead(tip, np.array([0.0, 0.0, -1.0]), reach=(high - low)[2] + 2e-3)


def test_a_growing_sphere_never_overtakes_where_the_tip_is_heading(small_box):
    """Frames go by while the worker is busy: the sphere around the moving tip asks for new nodes
    every frame, the predicted exit face stays the same and is asked once. The exit face is still
    served first (a contact there would otherwise wait for its columns: 150 ms at 10k nodes)."""
    tissue, tip, path = straight_through(small_box)
    prefetcher = Prefetcher(tissue)
    try:
        prefetcher._closed = True  # the worker is busy: nothing is served while frames go by
        prefetcher._thread.join()
        prefetcher.ahead(path)
        heading = prefetcher.requests[0]
        for frame in range(5):  # the tip moves on, its sphere takes in more nodes each frame
            prefetcher.near(tip - np.array([0.0, 0.0, frame * 1e-3]), radius=(frame + 1) * 1e-3)
            prefetcher.ahead(path)  # the same prediction: not asked again
        requests = prefetcher.requests
        assert len(requests) > 2 and requests[0] == heading
        assert prefetcher._next_chunk() == heading[:3]
        assert prefetcher.requests[0] == heading[3:]  # the rest of it before any sphere
    finally:
        prefetcher.close()


def test_a_path_through_the_wall_asks_for_the_exit_face_after_the_entry(small_box):
    """A path entering the top face and leaving through the bottom one: both faces' triangles, in order."""
    tissue, _, path = straight_through(small_box)
    low, high = small_box.points.min(axis=0), small_box.points.max(axis=0)
    prefetcher = Prefetcher(tissue)
    try:
        prefetcher._closed = True
        prefetcher._thread.join()
        prefetcher.ahead(path)
        heights = small_box.points[prefetcher.requests[0], 2]
        assert np.allclose(heights[:3], high[2])  # the entry triangle first ...
        on_bottom = np.flatnonzero(np.isclose(heights, low[2]))
        assert len(on_bottom) >= 3 and on_bottom.min() > 2  # ... then the exit face's
    finally:
        prefetcher.close()


def test_the_arc_ahead_continues_the_needle_circle():
    from sim.geometry import circle_through
    from sim.needle import Needle

    needle = Needle.curved()
    path = arc_ahead(needle.vertices, reach=0.004, segments=8)
    v = needle.vertices
    centre, radius = circle_through(v[0], v[len(v) // 2], v[-1])
    np.testing.assert_allclose(np.linalg.norm(path - centre, axis=1), radius, rtol=1e-9)
    np.testing.assert_allclose(path[0], needle.vertices[0], atol=1e-15)
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    chord = 2 * radius * np.sin(0.004 / radius / 8 / 2)
    np.testing.assert_allclose(steps, chord, rtol=1e-9)
    # it goes on from the tip, away from the rest of the needle
    assert np.linalg.norm(path[1] - needle.vertices[1]) > np.linalg.norm(path[0] - needle.vertices[1])


def test_a_straight_needle_looks_ahead_along_its_axis():
    vertices = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.001], [0.0, 0.0, 0.002]])
    np.testing.assert_allclose(arc_ahead(vertices, reach=0.01), [[0, 0, 0], [0, 0, -0.01]])


def test_a_worker_is_started_only_where_a_contact_could_need_columns(small_box, tmp_path):
    from sim.runtime.prefetch import needs_column_worker as _on_demand

    fixed = small_box.node_sets["z0"]
    on_demand = TissueModel(small_box, Material(20e3, 0.45), fixed)
    assert _on_demand(on_demand)
    every_free_node = TissueModel(small_box, Material(20e3, 0.45), fixed)
    every_free_node.precompute(tmp_path)  # candidates: every surface node not clamped
    assert not _on_demand(every_free_node)
    top_only = TissueModel(small_box, Material(20e3, 0.45), fixed, contact_nodes=small_box.node_sets["z1"])
    top_only.precompute(tmp_path)  # the sides are free surface outside the candidates
    assert _on_demand(top_only)


def test_a_column_evicted_from_the_cache_is_asked_for_again(small_box):
    column_bytes = 3 * small_box.n_nodes * 3 * 8
    tissue = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"], column_cache_bytes=1)
    prefetcher = Prefetcher(tissue)
    try:
        prefetcher._closed = True  # serve the queue by hand
        prefetcher._thread.join()
        prefetcher.near(small_box.points[0], radius=1e-9)
        assert prefetcher._next_chunk() == [0]
        prefetcher._pending.clear()
        tissue.prefetch([0])
        prefetcher.near(small_box.points[0], radius=1e-9)
        assert not prefetcher.requests  # cached: nothing to ask
        tissue.prefetch([1])  # the budget holds one node's columns: node 0's are evicted
        assert tissue.needs_solve(0, full=True) and column_bytes > 1
        assert tissue.evicted_columns == {0}  # named for the telemetry
        prefetcher.near(small_box.points[0], radius=1e-9)
        assert prefetcher.requests == [[0]]
        prefetcher.near(small_box.points[0], radius=1e-9)
        assert prefetcher.requests == [[0]]  # queued once, not once per frame
    finally:
        prefetcher.close()


def test_a_needle_still_in_the_air_already_asks_for_its_exit_face(small_box):
    """Before the first touch the graphics layer asks for the entry on the line of motion and for
    the far face the needle's own curve would come out of: a thin wall is crossed too soon after
    the touch for the worker to solve the exit face only then."""
    from sim.devices import ScriptedDevice, SuturingPass
    from sim.needle import Needle
    from sim.runtime import Simulation
    from sim.runtime.snapshots import FemSnapshot

    tissue = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["x0"])
    needle = Needle.curved()
    stitch = SuturingPass(needle, [0.002, 0.0025, 0.003], [0, 0, 1], [1, 0, 0])
    simulation = Simulation(tissue, needle, ScriptedDevice(stitch.pose_and_grip), forces=PAPER)
    vertices = needle.world_vertices(stitch.pose_and_grip(0.4)[0])  # approaching, 2 mm above the top
    free = FemSnapshot(0.4, np.zeros(3), vertices, "free", np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    simulation._prefetcher = prefetcher = Prefetcher(tissue, simulation.interaction.collision)
    try:
        prefetcher._closed = True
        prefetcher._thread.join()
        simulation._previous_tip = vertices[0] + [0.0, 0.0, 1e-4]  # moving down
        simulation._prefetch_ahead_of(free)
        first, *rest = prefetcher.requests
        heights = small_box.points[:, 2]
        assert np.allclose(heights[first[:3]], heights.max())  # the entry, on the line of motion, first
        asked = [n for request in rest for n in request]
        assert np.any(heights[asked] < heights.max() - 1e-6)  # and the far face the curve comes out of
    finally:
        simulation._prefetcher = None
        prefetcher.close()


def test_columns_at_are_rows_of_the_penalised_inverse_in_the_order_asked(model, tmp_path):
    import scipy.sparse.linalg as sla

    model.precompute(tmp_path)
    nodes, rows = np.array([17, 3, 40]), np.array([9, 0, 120, 5])
    stiffness = model.penalised_stiffness().tocsc()
    rhs = np.zeros((stiffness.shape[0], 9))
    rhs[(3 * nodes[:, None] + np.arange(3)).ravel(), np.arange(9)] = 1.0
    expected = sla.spsolve(stiffness, rhs)[rows]  # SciPy's SuperLU, not our CHOLMOD factor
    np.testing.assert_allclose(
        model.columns_at(nodes, rows), expected, rtol=1e-9, atol=1e-12 * abs(expected).max()
    )


def test_live_stress_prefetches_whole_columns_so_its_operator_needs_no_solve(small_box, tmp_path):
    """Issue 21: the local-stress operator reads rows of the load nodes' whole K0^-1 columns. With
    live stress the prefetcher caches them for precomputed candidates too (the precomputed matrix
    holds only candidate rows), and building the operator at contact then solves nothing."""
    from sim.fem.fields import LocalStress

    tissue = BiphaseTissue.build(small_box, small_box.node_sets["z0"])
    tissue.precompute(tmp_path)
    top = small_box.node_sets["z1"]
    nodes = top[
        np.argsort(np.linalg.norm(small_box.points[top] - small_box.points[top].mean(axis=0), axis=1))[:3]
    ]
    assert not tissue.soft.needs_solve(int(nodes[0])) and tissue.soft.needs_solve(int(nodes[0]), full=True)
    direct = LocalStress(tissue, nodes, np.eye(9), [small_box.points[nodes].mean(axis=0)])  # solves here
    fresh = BiphaseTissue.build(small_box, small_box.node_sets["z0"])
    fresh.precompute(tmp_path)
    prefetcher = Prefetcher(fresh, full_columns=True)
    try:
        assert prefetcher.on_demand  # the sphere around the tip is asked for even when precomputed
        prefetcher.near(small_box.points[nodes].mean(axis=0), radius=0.0015)
        deadline = time.monotonic() + 30
        while any(fresh.soft.needs_solve(int(n), full=True) for n in nodes) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert prefetcher.error is None
        import threading

        solved, here, worker_solve = [], threading.current_thread(), fresh.soft.column_solver

        def counting(ids):  # only what building the operator solves (the prefetch thread may go on)
            if threading.current_thread() is here:
                solved.append(ids)
            return worker_solve(ids)

        fresh.soft.column_solver = counting
        operator = LocalStress(fresh, nodes, np.eye(9), [small_box.points[nodes].mean(axis=0)])
        assert solved == []
        forces = np.random.default_rng(3).normal(size=9)
        assert operator.maximum(forces) == pytest.approx(direct.maximum(forces), rel=1e-12)
    finally:
        prefetcher.close()


def test_a_live_stress_run_starts_a_worker_for_a_precomputed_model(small_box, tmp_path):
    from sim.devices import ScriptedDevice
    from sim.needle import Needle, Pose
    from sim.runtime import RuntimeSettings, Simulation

    tissue = BiphaseTissue.build(small_box, small_box.node_sets["z0"])
    tissue.precompute(tmp_path)  # every free surface node a candidate: no worker without live stress
    for live, expected in ((False, False), (True, True)):
        device = ScriptedDevice(lambda t: (Pose(np.array([0.0, 0.0, 0.05]), np.eye(3)), False))
        simulation = Simulation(
            tissue, Needle.curved(), device, RuntimeSettings(live_stress_in_real_time=live)
        )
        simulation.interaction.live_stress = live
        try:
            simulation._start_prefetching(whole_columns=live)  # as run_realtime asks
            assert (simulation._prefetcher is not None) == expected
            if expected:
                assert simulation._prefetcher.full_columns
        finally:
            simulation.close()


def test_a_real_time_run_asks_for_its_bites_exit_faces_from_the_start(tmp_path):
    """Seen at the station: the worker, asked for a first exit's nodes only once the needle was in the
    wall, had 24 unsolved when it came out (a 0.2 s wait). As a real-time run starts, the nodes round
    where a needle planned square on each bite comes out are asked for, and solved whole, before any
    needle is near."""
    from sim.devices import ScriptedDevice
    from sim.devices.suturing import planned_exits
    from sim.needle import Needle, Pose
    from sim.runtime import Simulation
    from sim.runtime.simulation import EXIT_REACH_KERNELS

    wall = box_mesh((0.006, 0.005, 0.0015), (12, 10, 3))  # a 1.5 mm wall held at two sides
    held = np.union1d(wall.node_sets["x0"], wall.node_sets["x1"])
    tissue = BiphaseTissue.build(wall, held)
    tissue.precompute(tmp_path)
    entry = np.array([0.002, 0.0025, 0.0015])
    device = ScriptedDevice(lambda t: (Pose(np.array([0.0, 0.0, 0.05]), np.eye(3)), False))
    simulation = Simulation(tissue, Needle.curved(0.003), device, bites=[(entry, (0, 0, 1), (1, 0, 0))])
    simulation.interaction.live_stress = True
    try:
        needle, collision = simulation.interaction.needle, simulation.interaction.collision
        sites = planned_exits(needle, collision, simulation.bites)
        # out through the far face, 0.4 mm on along the bite (a 3 mm circle turned 30 deg down 1.5 mm)
        assert len(sites) and np.linalg.norm(sites - [0.0024, 0.0025, 0.0], axis=1).min() < 0.15e-3, sites
        reach = EXIT_REACH_KERNELS * simulation.interaction.forces.kernel_radius
        surface = np.setdiff1d(wall.surface_nodes, held)
        near = [surface[np.linalg.norm(wall.points[surface] - site, axis=1) <= reach] for site in sites]
        wanted = np.unique(np.concatenate(near))
        assert wanted.size and all(tissue.soft.needs_solve(int(n), full=True) for n in wanted)
        simulation._start_prefetching(whole_columns=True)  # as run_realtime does, then asks
        simulation._ask_for_exit_sites()
        deadline = time.monotonic() + 30
        while any(tissue.soft.needs_solve(int(n), full=True) for n in wanted) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert simulation._prefetcher.error is None
        assert not any(tissue.soft.needs_solve(int(n), full=True) for n in wanted)
    finally:
        simulation.close()
