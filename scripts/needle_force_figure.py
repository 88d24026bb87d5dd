"""Draw docs/figures/needle_force_curve.png: the needle force of scripted stitches on the wall-stitch task.

Run:  .venv/bin/python scripts/needle_force_figure.py

Left: force against the tip's depth below the entry surface for the expert (perpendicular, turning
along the curve) pass, with the puncture and emergence peaks Frick et al. 2001 describe. Middle: force
against time for the expert and three trainee profiles (levering loads the wall until it tears at the
preset's tear force). Right: the wall pressed to 1 mm and drawn back out at several speeds through the
runtime's contact law (puncture lifted): Frick et al. found no effect of speed between 1 and 10 mm/s;
unloading follows the rest curve, so no cycle returns more work than it took.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from sessions.tasks import task_preset, task_spec, tissue_for
from sim.calibration.indentation import load_cycle
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import SuturingPassParameters
from sim.needle import Needle
from sim.runtime import Simulation

PROFILES = {
    "expert": SuturingPassParameters(),
    "25 deg entry": SuturingPassParameters(entry_angle_deg=25.0),
    "levering (wrist 0.5)": SuturingPassParameters(wrist_rotation=0.5),
    "hesitant, 15 deg": SuturingPassParameters(hesitations=2, entry_angle_deg=15.0, wrist_rotation=0.7),
}


def stitch(tissue, parameters):
    spec = task_spec("wall-stitch")
    suturing = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction, parameters)
    simulation = Simulation(
        tissue,
        Needle.curved(),
        ScriptedDevice(suturing.pose_and_grip),
        forces=task_preset(task_spec("wall-stitch")).forces,
    )
    rows = []
    simulation.on_sample = lambda now, sample, force, fem: rows.append(
        (now, spec.entry[2] - fem.needle_vertices[0][2], float(np.linalg.norm(fem.needle_force)), fem.state)
        if fem is not None
        else (now, np.nan, 0.0, "free")
    )
    simulation.run_simulated(suturing.duration)
    time, depth, force, state = zip(*rows, strict=True)
    return np.array(time), np.array(depth), np.array(force), np.array(state)


def main() -> None:
    tissue = tissue_for(task_spec("wall-stitch"), None)
    figure, (left, right, speeds) = plt.subplots(1, 3, figsize=(15, 4.2), dpi=110)
    time, depth, force, state = stitch(tissue, PROFILES["expert"])
    inserting = (
        (state == "contact")
        | (state == "pierced")
        | ((state == "exited") & (time < time[state == "exited"][0] + 0.2))
    )
    left.plot(depth[inserting] * 1e3, force[inserting] * 1e3, color="black")
    first = np.flatnonzero(state == "pierced")[0]
    exit_ = np.flatnonzero(state == "exited")[0]
    left.annotate(
        "puncture (entry peak)",
        (depth[first - 1] * 1e3, force[first - 1] * 1e3),
        xytext=(0.2, 640),
        arrowprops={"arrowstyle": "->"},
    )
    left.annotate(
        "emergence peak",
        (depth[exit_ - 1] * 1e3, force[exit_ - 1] * 1e3),
        xytext=(1.1, 750),
        arrowprops={"arrowstyle": "->"},
    )
    left.axhline(800, color="tab:red", lw=0.8, ls="--")
    left.text(0.02, 815, "puncture force 800 mN", color="tab:red", fontsize=8)
    left.set_xlabel("tip depth below the entry surface (mm)")
    left.set_ylabel("needle force (mN)")
    left.set_title("expert pass: force against depth")
    for name, parameters in PROFILES.items():
        t, _, f, _ = stitch(tissue, parameters)
        right.plot(
            t,
            f * 1e3,
            label=name,
            lw=1.0 if name != "expert" else 1.6,
            color="black" if name == "expert" else None,
        )
    right.set_xlabel("time (s)")
    right.set_ylabel("needle force (mN)")
    right.set_title("force against time, four profiles")
    right.legend(fontsize=8)
    spec, forces = task_spec("wall-stitch"), task_preset(task_spec("wall-stitch")).forces
    for speed in (0.001, 0.01, 0.1, 0.5):
        cycle = load_cycle(tissue, forces, spec.entry, spec.normal, 1e-3, speed, speed)
        line = speeds.plot(
            cycle.loading_depth * 1e3, cycle.loading_force * 1e3, label=f"{speed * 1e3:g} mm/s in"
        )
        speeds.plot(
            cycle.unloading_depth * 1e3,
            cycle.unloading_force * 1e3,
            color=line[0].get_color(),
            ls=":",
            lw=1.0,
        )
    speeds.set_xlim(0, 1.0)
    speeds.set_xlabel("indentation (mm)")
    speeds.set_ylabel("normal force (mN)")
    speeds.set_title("pressed and drawn back (dotted) at four speeds")
    speeds.legend(fontsize=8, title="1 and 10 mm/s overlap (Frick 2001)", title_fontsize=7)
    figure.tight_layout()
    out = Path(__file__).parents[1] / "docs" / "figures" / "needle_force_curve.png"
    figure.savefig(out)
    print(out)


if __name__ == "__main__":
    main()
