"""Tissue-core figures of issue 2: assembly, factorisation, precompute, per-tick costs.

Run:  .venv/bin/python benchmarks/precompute.py [--quick] [--scenarios a,b]

For each scenario prints: assembly, factorisation of K0, full precompute (the
exact condensed inverse over every contact candidate), memory of the stored
columns, reaction force for one contact triangle per haptic tick (linear and
biphase), surface displacement for display, on-demand contact-change solve, and
the ratio to the paper's Table 2 solve time where it gives one. On the 2283-node
model the straightforward CHOLMOD multi-RHS route is timed in the same process
as the reference. Times are medians of repeats.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from sim.calibration.scenarios import SCENARIOS, scenario
from sim.fem import BiphaseParameters, Material, TissueModel
from sim.fem.biphase import BiphaseContact
from sim.fem.inverse.condensation import condensed_inverse_multi_rhs, node_dofs

PRECOMPUTED = ("paper_table2_792", "paper_table2_1286", "paper_table2_2283", "vessel_10k")
ON_DEMAND_ONLY = ("vessel_50k",)


def median_seconds(function: Callable[[], object], repeats: int) -> float:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return float(np.median(samples))


def per_call_seconds(function: Callable[[], object], calls: int, repeats: int = 5) -> float:
    def batch() -> None:
        for _ in range(calls):
            function()

    return median_seconds(batch, repeats) / calls


def contact_triangle(model: TissueModel) -> np.ndarray:
    """A surface triangle all of whose nodes are contact candidates, near the candidates' centre."""
    mesh = model.mesh
    ok = np.all(np.isin(mesh.surface_triangles, model.contact_nodes), axis=1)
    centroids = mesh.points[mesh.surface_triangles].mean(axis=1)
    target = mesh.points[model.contact_nodes].mean(axis=0)
    distance = np.where(ok, np.linalg.norm(centroids - target, axis=1), np.inf)
    return mesh.surface_triangles[int(np.argmin(distance))]


def tick_figures(model: TissueModel, stiff: TissueModel, triangle: np.ndarray) -> dict[str, float]:
    weights = np.array([0.5, 0.3, 0.2])
    d = np.array([1e-4, -2e-4, -5e-4])
    handle = model.contact(triangle)
    biphase = BiphaseContact(handle, stiff.contact(triangle), BiphaseParameters(), depth=1.5e-3)

    def force_tick() -> None:
        handle.reaction_forces(np.outer(weights, d))

    def biphase_tick() -> None:
        biphase.reaction_forces(np.outer(weights, d), d, 0.004)

    reactions = handle.reaction_forces(np.outer(weights, d))
    return {
        "force_tick_us": 1e6 * per_call_seconds(force_tick, 20000),
        "biphase_tick_us": 1e6 * per_call_seconds(biphase_tick, 20000),
        "display_ms": 1e3 * per_call_seconds(lambda: handle.surface_displacement(reactions), 200),
        "display_rows": len(handle.surface_nodes),
    }


def run_precomputed(name: str, repeats: int) -> dict[str, object]:
    case = scenario(name)
    soft = TissueModel(case.mesh, Material(20e3, 0.45), case.fixed_nodes, contact_nodes=case.contact_nodes)
    stiff = TissueModel(case.mesh, Material(40e3, 0.45), case.fixed_nodes, contact_nodes=case.contact_nodes)

    def assemble() -> None:
        fresh = TissueModel(
            case.mesh, Material(20e3, 0.45), case.fixed_nodes, contact_nodes=case.contact_nodes
        )
        fresh.penalised_stiffness()

    def factorise() -> None:
        from sim.fem.inverse.condensation import sparse_cholesky

        sparse_cholesky(soft.penalised_stiffness())

    out: dict[str, object] = {
        "scenario": name,
        "nodes": case.mesh.n_nodes,
        "elements": case.mesh.n_elements,
        "candidates": len(case.contact_nodes),
        "assembly_s": median_seconds(assemble, repeats),
        "factorisation_s": median_seconds(factorise, repeats),
        "precompute_s": median_seconds(lambda: soft.precompute(use_cache=False), repeats),
    }
    out.update({f"last_{k}_s": v for k, v in soft.precomputation.seconds.items()})
    stiff.precompute(use_cache=False)
    out["stored_mb"] = soft.precomputation.nbytes / 2**20
    triangle = contact_triangle(soft)
    out.update(tick_figures(soft, stiff, triangle))
    on_demand = TissueModel(
        case.mesh, Material(20e3, 0.45), case.fixed_nodes, contact_nodes=case.contact_nodes
    )
    on_demand.penalised_stiffness()
    on_demand._factor  # noqa: B018 - factorise before timing contact changes
    out["contact_change_ms"] = 1e3 * on_demand_change_seconds(on_demand, triangle, repeats)
    if case.paper_seconds:
        out["paper_s"] = case.paper_seconds
        out["speedup_vs_paper"] = case.paper_seconds / out["precompute_s"]
    if name == "paper_table2_2283":
        k0 = soft.penalised_stiffness()
        dofs = node_dofs(soft.contact_nodes)
        reference = median_seconds(lambda: condensed_inverse_multi_rhs(k0, dofs), repeats)
        out["reference_multi_rhs_s"] = reference
        out["ratio_vs_multi_rhs"] = reference / out["precompute_s"]
    return out


def on_demand_change_seconds(model: TissueModel, triangle: np.ndarray, repeats: int) -> float:
    """Time to answer a new contact triangle whose columns are not cached yet."""

    def change() -> None:
        model.drop_cached_columns()
        model.contact(triangle)

    return median_seconds(change, repeats)


def run_on_demand(name: str, repeats: int) -> dict[str, object]:
    case = scenario(name)
    soft = TissueModel(case.mesh, Material(20e3, 0.45), case.fixed_nodes, contact_nodes=case.contact_nodes)
    stiff = TissueModel(case.mesh, Material(40e3, 0.45), case.fixed_nodes, contact_nodes=case.contact_nodes)
    start = time.perf_counter()
    soft.penalised_stiffness()
    assembly = time.perf_counter() - start
    start = time.perf_counter()
    soft._factor  # noqa: B018
    factorisation = time.perf_counter() - start
    triangle = contact_triangle(soft)
    out: dict[str, object] = {
        "scenario": name,
        "nodes": case.mesh.n_nodes,
        "elements": case.mesh.n_elements,
        "candidates": len(case.contact_nodes),
        "assembly_s": assembly,
        "factorisation_s": factorisation,
        "contact_change_ms": 1e3 * on_demand_change_seconds(soft, triangle, repeats),
        "stored_mb": 9 * 3 * case.mesh.n_nodes * 8 / 2**20,
    }
    out.update(tick_figures(soft, stiff, triangle))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="one repeat, skip the 50k-node mesh")
    parser.add_argument("--scenarios", default=",".join(PRECOMPUTED + ON_DEMAND_ONLY))
    args = parser.parse_args()
    names = [n for n in args.scenarios.split(",") if n]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        parser.error(f"unknown scenario(s) {unknown}; choose from {list(SCENARIOS)}")
    for name in names:
        if args.quick and name in ON_DEMAND_ONLY:
            continue
        repeats = 1 if args.quick else (5 if name.startswith("paper") else 3)
        row = run_on_demand(name, repeats) if name in ON_DEMAND_ONLY else run_precomputed(name, repeats)
        print_row(row)


def print_row(row: dict[str, object]) -> None:
    parts = []
    for key, value in row.items():
        parts.append(f"{key}={value:.4g}" if isinstance(value, float) else f"{key}={value}")
    print("  ".join(parts), flush=True)


if __name__ == "__main__":
    main()
