"""The subordinate hand's figures of issue 46: which grasp rule converges, and what both hands cost.

Run:  .venv/bin/python benchmarks/forceps.py [--repeats 3]
      [--part convergence|cost|realtime|eversion|inside-edge|all]

- convergence: the force to lift a 1.5 mm wall patch's wound edge 0.5 mm with the forceps (the
  porcine-artery preset's soft phase, 300 kPa), by the jaws rule (every surface node within the
  1.5 mm jaws' footprint) and the source paper's triangle rule (the nearest triangle's three nodes),
  on uniform meshes of 0.5, 0.3, 0.2 and 0.15 mm cells;
- cost: on the interrupted stitch's 6,624-node patch, a scripted expert's whole stitch in simulated
  time with both hands against the needle hand alone: the FEM step's median and p99 compute (the
  budget: <= 200 us), the haptic step's, and the wall time of building a grasp (the grasped nodes'
  K0^-1 columns solved, then the three unit patterns), median over ``--repeats``;
- realtime: the same stitch on the real-time clock, ``--repeats`` runs: the grasp's contact change
  (the FEM step reading the closed jaws to the grasp's forces; the task's grasp sites solved before
  the clock), and the FEM and haptic steps' compute with both hands;
- eversion: on the interrupted stitch's artery, the scripted hand's grasp at the wound's rim lifted
  0.05-1 mm along the entry's normal: how far the wall's outward normal at the bite's entry (the
  collision mesh's triangles within 0.35 mm of it, as the graphics layer moves them) turns, which
  way, and the forceps' force. What an eversion buys a needle that must enter square, and what a
  task needing one would ask of the hand (linear kinematics: turns past ~10 deg are first-order).
- inside-edge: the task that cannot be done square without the forceps (the wrist stops 7 deg short
  of square to the resting wall): the entry angle at first touch of scripted hands (experts 0.95 and
  trainees 0.3, seeds 1-8) with both hands and with the forceps leaving the edge alone, and of a
  needle planned square to the resting wall.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

# This folder holds scripts named like our packages (metrics.py, recorder.py): keep it off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from sim.calibration.presets import tissue_preset  # noqa: E402
from sim.collision.mesh import CollisionMesh  # noqa: E402
from sim.fem import Material, TissueModel  # noqa: E402
from sim.forceps import Forceps, ForcepsInteraction  # noqa: E402
from sim.mesh import box_mesh  # noqa: E402

LIFT = 0.5e-3
SIZE = (0.012, 0.01, 0.0015)


def lifting_force(cell: float, rule: str) -> tuple[int, int, float]:
    """(nodes in the mesh, nodes grasped, force (N)) to lift the patch's free edge by LIFT."""
    divisions = tuple(max(1, round(s / cell)) for s in SIZE)
    mesh = box_mesh(SIZE, divisions)
    fixed = np.concatenate([mesh.node_sets[k] for k in ("x0", "y0", "y1")])
    soft = tissue_preset("porcine-artery").biphase
    model = TissueModel(mesh, Material(soft.soft_modulus, soft.poisson_ratio), fixed)
    hand = ForcepsInteraction(model, CollisionMesh(mesh), Forceps(rule=rule))
    jaw = np.array([SIZE[0], SIZE[1] / 2, SIZE[2] / 2])  # on the cut face, mid-wall
    hand.hold(0.0, jaw, True)
    hand.hold(0.0, jaw + np.array([0.0, 0.0, LIFT]), True)
    step = hand.fem_step(0.0)
    return mesh.n_nodes, step.nodes.size, float(np.linalg.norm(step.force))


def convergence() -> None:
    print(f"force to lift the wound edge {LIFT * 1e3:g} mm (porcine-artery soft phase), by rule and cell:")
    heads = ("cell (mm)", "nodes", "jaws: grasped", "force (mN)", "triangle", "force (mN)")
    print("  ".join(f"{h:>{w}}" for h, w in zip(heads, (9, 6, 13, 10, 8, 10), strict=True)))
    for cell in (0.5e-3, 0.3e-3, 0.2e-3, 0.15e-3):
        n, jaws_nodes, jaws = lifting_force(cell, "jaws")
        _, tri_nodes, triangle = lifting_force(cell, "triangle")
        line = f"{cell * 1e3:9.2f}  {n:6d}  {jaws_nodes:13d}  {jaws * 1e3:10.1f}  "
        print(line + f"{tri_nodes:8d}  {triangle * 1e3:10.1f}")


def cost(repeats: int) -> None:
    from sessions.running.runner import SessionPlan, open_device
    from sessions.synthetic import scripted_hands
    from sessions.tasks import task_simulation, task_spec, tissue_for
    from sim.devices.assisting import edge_grasp

    task = "interrupted-stitch"
    tissue = tissue_for(task_spec(task))
    print(f"{task}: {tissue.mesh.n_nodes} nodes; a scripted expert's whole stitch, simulated time")
    rows = {}
    for hands in ("needle hand alone", "both hands"):
        fem, haptic, walls = [], [], []
        for seed in range(repeats):
            both = scripted_hands(0.95, seed)
            plan = SessionPlan("benchmark", "E", task, 1)
            given = both if hands == "both hands" else both.needle
            device, duration, subordinate = open_device("scripted", plan, None, given)
            options = {} if subordinate is None else {"subordinate": subordinate}
            simulation = task_simulation(task_spec(task), device, **options)
            began = time.perf_counter()
            simulation.run_simulated(duration)
            walls.append(time.perf_counter() - began)
            fem.append(simulation.telemetry["fem"].computes)
            haptic.append(simulation.telemetry["haptic"].computes)
        fem_all, haptic_all = np.concatenate(fem), np.concatenate(haptic)
        rows[hands] = (
            np.median(fem_all),
            np.percentile(fem_all, 99),
            np.median(haptic_all),
            np.median(walls),
        )
    print(f"{'':>18}  {'FEM p50 (us)':>12}  {'FEM p99 (us)':>12}  {'haptic p50 (us)':>15}  {'wall (s)':>8}")
    for hands, (p50, p99, h50, wall) in rows.items():
        print(f"{hands:>18}  {p50 * 1e6:12.0f}  {p99 * 1e6:12.0f}  {h50 * 1e6:15.1f}  {wall:8.2f}")
    builds = []
    for _ in range(repeats):
        tissue.base.drop_cached_columns()
        hand = ForcepsInteraction(tissue, CollisionMesh(tissue.mesh))
        spec = task_spec(task)
        rim, _ = edge_grasp(
            spec.entry, spec.normal, spec.placement["wound_point"], spec.placement["wound_normal"]
        )
        began = time.perf_counter()
        hand.hold(0.0, rim, True)
        builds.append(time.perf_counter() - began)
    built = np.median(builds) * 1e3
    print(f"building a grasp ({hand.nodes.size} nodes, columns from cold): median {built:.0f} ms")


def realtime(repeats: int) -> None:
    """A scripted expert's two-handed stitch on the real-time clock, ``repeats`` seeds: the grasp's
    contact change (the FEM step reading the closed jaws to the grasp's forces), warm (the task's grasp
    sites solved before the clock, the prefetcher ahead of the jaws) and the layers' compute."""
    from sessions.running.runner import SessionPlan, open_device
    from sessions.synthetic import scripted_hands
    from sessions.tasks import task_simulation, task_spec

    task = "interrupted-stitch"
    grasps, fem50, fem99, haptic50 = [], [], [], []
    for seed in range(repeats):
        plan = SessionPlan("benchmark", "E", task, 1)
        device, duration, subordinate = open_device("scripted", plan, None, scripted_hands(0.95, seed))
        simulation = task_simulation(task_spec(task), device, subordinate=subordinate)
        result = simulation.run_realtime(duration)
        grasps += simulation.contact_latencies["grasp"]
        fem50.append(result.telemetry["fem"].compute_p50)
        fem99.append(result.telemetry["fem"].compute_p99)
        haptic50.append(result.telemetry["haptic"].compute_p50)
    latency = np.array(grasps) * 1e3
    print(f"{task}, real time, both hands, {repeats} runs, {latency.size} grasps:")
    print(
        f"  grasp contact change: median {np.median(latency):.2f} ms, "
        f"p99 {np.percentile(latency, 99):.2f} ms, max {latency.max():.2f} ms"
    )
    print(
        f"  FEM step compute: p50 {np.median(fem50) * 1e6:.0f} us, p99 {np.median(fem99) * 1e6:.0f} us "
        f"(medians over runs); haptic step p50 {np.median(haptic50) * 1e6:.0f} us"
    )


def eversion() -> None:
    from sessions.tasks import task_spec, tissue_for
    from sessions.tasks.build import edge_grasps

    spec = task_spec("interrupted-stitch")
    tissue = tissue_for(spec)
    collision = CollisionMesh(tissue.mesh)
    hand = ForcepsInteraction(tissue, collision)
    rim, lift = edge_grasps(spec)[0]
    entry, normal, towards_wound = (np.asarray(v) for v in (spec.entry, spec.normal, spec.bite_direction))
    centres = collision.corners.mean(axis=1)
    near = (np.linalg.norm(centres - entry, axis=1) < 0.35e-3) & (collision.normals @ normal > 0.9)
    hand.hold(0.0, rim, True)
    print(f"interrupted stitch: the rim grasped ({hand.nodes.size} nodes), lifted along the entry's normal:")
    print(f"{'lift (mm)':>9}  {'normal turned (deg)':>19}  {'towards':>16}  {'forceps force (mN)':>18}")
    for lifted in (0.05e-3, 0.12e-3, 0.25e-3, 0.5e-3, 0.75e-3, 1e-3):
        hand.hold(0.1, rim + lifted * lift, True)
        step = hand.fem_step(0.1)
        hand.deform_collision()
        turned = collision.normals[near].mean(axis=0)
        turned /= np.linalg.norm(turned)
        angle = np.degrees(np.arccos(np.clip(turned @ normal, -1.0, 1.0)))
        way = "the wound" if turned @ towards_wound > 0 else "away from wound"
        print(f"{lifted * 1e3:9.2f}  {angle:19.2f}  {way:>16}  {np.linalg.norm(step.force) * 1e3:18.0f}")


def inside_edge() -> None:
    import dataclasses

    from sessions.running.runner import SessionPlan, open_device
    from sessions.synthetic import scripted_hands
    from sessions.tasks import task_simulation, task_spec
    from sim.devices import ScriptedDevice, SuturingPass
    from sim.needle import Needle

    spec = task_spec("inside-edge")

    def touch(simulation, duration) -> tuple[float, float, int]:
        """(entry angle at first touch (deg), how much bigger than asked the bite was there (mm:
        the touch's distance from the mark away from the wound), unsafe events)."""
        simulation.run_simulated(duration)
        kinds = [e.kind for e in simulation.events]
        first = next(e for e in simulation.events if e.kind == "contact_start")
        point = np.asarray(first.barycentric) @ simulation.interaction.collision.corners[first.triangle]
        bigger = -float((point - np.asarray(spec.entry)) @ np.asarray(spec.bite_direction)) * 1e3
        unsafe = sum(
            kinds.count(k) for k in ("overstress", "edge_overstress", "tear", "edge_torn", "implausible_hit")
        )
        return first.entry_angle_deg, bigger, unsafe

    short, lift, turn = spec.eversion.short_deg, spec.eversion.lift_m * 1e3, spec.eversion.turn_deg
    print(f"inside-edge: the wrist stops {short:g} deg short of square to the resting wall;")
    print(f"the task's eversion lifts the rim {lift:g} mm, turning the wall {turn:g} deg")
    print(
        "entry angle at first touch (deg) and, in brackets, how much bigger the bite is there (mm), seeds 1-8"
    )
    for label, skill in (("expert 0.95", 0.95), ("trainee 0.3", 0.3)):
        for grasps in (True, False):
            cells, unsafe = [], 0
            for seed in range(1, 9):
                hands = scripted_hands(skill, seed)
                assisting = hands.assisting if grasps else dataclasses.replace(hands.assisting, grasps=False)
                hands = dataclasses.replace(hands, assisting=assisting)
                device, duration, sub = open_device(
                    "scripted", SessionPlan("s", "p", spec.name, 1), None, hands
                )
                angle, bigger, bad = touch(task_simulation(spec, device, None, subordinate=sub), duration)
                cells.append(f"{angle:.1f} ({bigger:+.2f})")
                unsafe += bad
            held = "evert the edge" if grasps else "leave it alone"
            print(f"  {label}, {held}: {' '.join(cells)}; unsafe events {unsafe}")
    planned = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction)
    angle, _, _ = touch(task_simulation(spec, ScriptedDevice(planned.pose_and_grip), None), planned.duration)
    open_angle, _, _ = touch(
        task_simulation(task_spec("interrupted-stitch"), ScriptedDevice(planned.pose_and_grip), None),
        planned.duration,
    )
    print(f"a needle planned square to the resting wall: {angle:.1f} deg")
    print(f"the same needle on the interrupted stitch (no stop): {open_angle:.1f} deg")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parts = ("convergence", "cost", "realtime", "eversion", "inside-edge", "all")
    parser.add_argument("--part", choices=parts, default="all")
    args = parser.parse_args()
    if args.part in ("convergence", "all"):
        convergence()
    if args.part in ("cost", "all"):
        cost(args.repeats)
    if args.part in ("realtime", "all"):
        realtime(args.repeats)
    if args.part in ("eversion", "all"):
        eversion()
    if args.part in ("inside-edge", "all"):
        inside_edge()


if __name__ == "__main__":
    main()
