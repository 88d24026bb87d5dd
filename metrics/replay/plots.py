"""Force, tip speed and stress against time, with the expert median and IQR band and event markers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from metrics.reading.figures import new_figure
from metrics.replay.reference import SIGNALS, ExpertReference, signal_of
from metrics.streams import SessionStreams
from sim.render import write_image

EVENT_STYLES = {
    "contact_start": ("contact", "tab:blue"),
    "pierce": ("pierce", "tab:red"),
    "exit": ("exit", "tab:green"),
    "regrab": ("re-grab", "tab:purple"),
    "release": ("release", "tab:gray"),
    "force_clamped": ("force clamp", "black"),
}


def signal_figure(session: SessionStreams, reference: ExpertReference | None = None, signals=tuple(SIGNALS)):
    """A matplotlib figure, one panel per signal the session has, sharing the time axis."""
    from matplotlib.lines import Line2D

    present = [name for name in signals if signal_of(session, name) is not None]
    figure = new_figure(figsize=(9, 2.2 * max(len(present), 1)))
    axes = figure.subplots(len(present), 1, sharex=True, squeeze=False)
    events = session.events
    for axis, name in zip(axes[:, 0], present, strict=True):
        label, factor = SIGNALS[name]
        values = signal_of(session, name) * factor
        if reference is not None:
            band = reference.band(session, name)
            axis.fill_between(
                session.time, band.lower * factor, band.upper * factor, color="tab:green", alpha=0.25,
                linewidth=0, label="experts, IQR",
            )  # fmt: skip
            axis.plot(
                session.time, band.median * factor, color="tab:green", linewidth=1.2, label="experts, median"
            )
        axis.plot(
            session.time, values, color="black", linewidth=1.0, label=session.participant_id or "session"
        )
        for kind, (_, colour) in EVENT_STYLES.items():
            for when in events.loc[events["kind"] == kind, "time"]:
                axis.axvline(when, color=colour, linewidth=0.8, linestyle="--")
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    if present:
        axes[0, 0].legend(loc="upper right", fontsize=8)
        handles = [
            Line2D([], [], color=colour, linestyle="--", label=text)
            for kind, (text, colour) in EVENT_STYLES.items()
            if (events["kind"] == kind).any()
        ]
        if handles:
            axes[-1, 0].legend(handles=handles, loc="upper right", fontsize=8, ncol=len(handles))
        axes[-1, 0].set_xlabel("time (s)")
    figure.suptitle(f"Session {session.session_id}" + (" vs experts" if reference is not None else ""))
    figure.tight_layout()
    return figure


def figure_pixels(figure, dpi: int = 100) -> NDArray[np.uint8]:
    """(H, W, 3) RGB pixels of a matplotlib figure."""
    figure.set_dpi(dpi)
    figure.canvas.draw()
    return np.asarray(figure.canvas.buffer_rgba())[:, :, :3].copy()


def write_signal_plots(
    session: SessionStreams, out_dir: str | Path, reference: ExpertReference | None = None, dpi: int = 100
) -> list[Path]:
    """``signals.png`` (through OpenImageIO) and ``signals.svg`` (vector, for papers) in ``out_dir``."""

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figure = signal_figure(session, reference)
    png = write_image(out / "signals.png", figure_pixels(figure, dpi))
    svg = out / "signals.svg"
    figure.savefig(svg)
    return [png, svg]
