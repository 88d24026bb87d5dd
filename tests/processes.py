"""The processes a test started, and whether they are gone (Linux /proc)."""

from __future__ import annotations

import os
import time


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (children, their children, ...), as /proc shows them now."""
    found, pending = [], [pid]
    while pending:
        parent = pending.pop()
        try:
            threads = os.listdir(f"/proc/{parent}/task")
        except FileNotFoundError:
            continue
        for thread in threads:
            try:
                with open(f"/proc/{parent}/task/{thread}/children") as children:
                    kids = [int(k) for k in children.read().split()]
            except FileNotFoundError:
                continue
            found += kids
            pending += kids
    return found


def ended(pid: int) -> bool:
    """Gone, or a zombie waiting to be reaped."""
    try:
        with open(f"/proc/{pid}/status") as status:
            return any(line.startswith("State:") and "Z" in line.split()[1] for line in status)
    except FileNotFoundError:
        return True


def still_running(pids: list[int], within: float) -> list[int]:
    """Those of ``pids`` still running after waiting up to ``within`` seconds for them to end."""
    deadline = time.monotonic() + within
    while True:
        alive = [pid for pid in pids if not ended(pid)]
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.05)


def started_under(folder: str) -> list[int]:
    """Running processes (other than this one and its ancestors) whose command line or environment
    names ``folder``: what a test run started there, wherever it has been re-parented since."""
    mine = {os.getpid(), os.getppid()}
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) in mine or ended(int(entry)):
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as cmdline, open(f"/proc/{entry}/environ", "rb") as env:
                if folder.encode() in cmdline.read() + env.read():
                    found.append(int(entry))
        except OSError:  # gone, or not ours to read
            continue
    return found
