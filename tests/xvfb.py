"""A virtual X display (Xvfb) for window tests and the station's benchmarks."""

from __future__ import annotations

import os
import subprocess


def start_virtual_display(size: str = "1366x768") -> tuple[subprocess.Popen, str]:
    """An Xvfb server on a display number it picks itself (``-displayfd``): (process, ":N").

    ``-noreset``: by default an X server resets when its last client leaves, and a window opening
    during the reset is refused (a station test between two others saw exactly that)."""
    read, write = os.pipe()
    server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write), "-screen", "0", f"{size}x24", "-nolisten", "tcp", "-noreset"],
        pass_fds=(write,),
        stderr=subprocess.DEVNULL,
    )
    os.close(write)
    number = b""
    while not number.endswith(b"\n"):
        chunk = os.read(read, 16)
        if not chunk:
            os.close(read)
            raise RuntimeError("Xvfb did not start (is the xvfb package installed?)")
        number += chunk
    os.close(read)
    return server, f":{int(number)}"
