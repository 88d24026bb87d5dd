"""Reproduce PAPER.md Table 1 (volume change vs strain, E1-only and biphase) on the test cube.

Run:  .venv/bin/python scripts/reproduce_table1.py
Prints a Markdown table for docs/reproduction.md: the paper's figures next to
ours, for the exact multi-point contact and for the paper's plain superposition,
at Poisson's ratio 0.45 and at the paper's maximum 0.47.
"""

from __future__ import annotations

from sim.calibration.indentation import indentation_curve
from sim.fem import BiphaseParameters

STRAINS = (0.02, 0.10, 0.20, 0.50)
PAPER = {0.02: ("< 0.5", "< 0.5"), 0.10: ("0.5", "0.5"), 0.20: ("0.8", "6.5"), 0.50: ("5", "25")}


def main() -> None:
    columns = {}
    for nu in (0.45, 0.47):
        for method in ("exact", "superposition"):
            curve = indentation_curve(STRAINS, BiphaseParameters(poisson_ratio=nu), method=method)
            columns[(nu, method)] = curve
    header = ["strain", "paper E1-only", "paper biphase"]
    for nu, method in columns:
        header += [f"E1-only, nu={nu}, {method}", f"biphase, nu={nu}, {method}"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for i, strain in enumerate(STRAINS):
        row = [f"{100 * strain:.0f} %", *PAPER[strain]]
        for curve in columns.values():
            row += [
                f"{100 * curve.volume_change_linear[i]:+.2f}",
                f"{100 * curve.volume_change_biphase[i]:+.2f}",
            ]
        print("| " + " | ".join(row) + " |")
    print()
    print("Normal reaction force (N) at the same strains, exact contact, nu = 0.45:")
    curve = columns[(0.45, "exact")]
    for i, strain in enumerate(STRAINS):
        linear, biphase = curve.force_linear[i], curve.force_biphase[i]
        print(f"- {100 * strain:.0f} %: E1-only {linear:.4f} N, biphase {biphase:.4f} N")


if __name__ == "__main__":
    main()
