"""The needle's contact law compiled (sim/needle/_contact_law.c) equals its NumPy reference: the law as
`sim.needle.load.kernel_step` wrote it before, kept here line for line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.errors import ModelError
from sim.fem import BiphaseParameters
from sim.fem.kernel import kernel_at
from sim.needle import _contact_law as compiled
from sim.needle.forces import NeedleForces
from sim.needle.load import KernelLoad, biphase_limits, kernel_step


def surface_contact(displacements, normals, ratio, friction):
    pressed = -np.einsum("ij,ij->i", displacements, normals)
    along = displacements + pressed[:, None] * normals
    size = np.sqrt(np.einsum("ij,ij->i", along, along))
    bound = friction * np.maximum(pressed, 0.0) / ratio
    slides = np.zeros_like(displacements)
    sliding = size > bound
    if not sliding.any():
        return displacements, slides
    kept = along[sliding] * (bound[sliding] / size[sliding])[:, None]
    slides[sliding] = along[sliding] - kept
    return displacements - slides, slides


def reference_step(law, displacements, extra, speed, indentation, surface):
    """The NumPy contact law (the reference the compiled one must equal): (forces, share, now, shifts,
    torn)."""
    compliance, soft, stiff, scale, parameters, depth, ratio, friction, tear = law

    def elastic_forces(d, share):
        d = d.reshape(-1)
        soft_forces = soft.dot(d)
        if share == 1.0:
            return soft_forces.reshape(-1, 3)
        if stiff is None:
            return ((share + (1.0 - share) * scale) * soft_forces).reshape(-1, 3)
        return (share * soft_forces + (1.0 - share) * stiff.dot(d)).reshape(-1, 3)

    displacements = np.array(displacements, dtype=np.float64)
    shifts = np.zeros_like(displacements)
    if surface is not None:
        displacements, slides = surface_contact(displacements, surface, ratio, friction)
        shifts += slides
    total = displacements
    if np.any(extra):
        total = displacements + compliance.dot(extra.reshape(-1)).reshape(-1, 3)
    now = float(np.sqrt(np.einsum("ij,ij->i", total, total).max()))
    loading = speed if now >= indentation else 0.0
    share = 1.0
    if parameters is not None:
        share = parameters.soft_share(now / depth, parameters.strain_limit_at(max(loading, 0.0)))
    if surface is None:
        elastic = elastic_forces(displacements, share)
    else:
        probe = np.zeros_like(displacements)
        stiffness = np.empty(len(surface))
        for m in range(len(surface)):
            probe[m] = surface[m]
            stiffness[m] = float(elastic_forces(probe, share)[m] @ surface[m])
            probe[m] = 0.0
        normal = np.einsum("ij,ij->i", displacements, surface)[:, None] * surface
        elastic = stiffness[:, None] * (normal + ratio * (displacements - normal))
    torn = []
    if tear is not None:
        sizes = np.sqrt(np.einsum("ij,ij->i", elastic, elastic))
        for m in np.flatnonzero(sizes > tear):
            factor = tear / sizes[m]
            shifts[m] += (1.0 - factor) * displacements[m]
            elastic[m] *= factor
            torn.append(int(m))
    return elastic + extra, share, now, shifts, tuple(torn)


def compiled_step(law, displacements, extra, speed, indentation, surface):
    compliance, soft, stiff, scale, parameters, depth, ratio, friction, tear = law
    m = len(displacements)
    forces, shifts, torn = np.empty((m, 3)), np.empty((m, 3)), np.empty(m, dtype=np.int64)
    share, now, count = compiled.step(
        np.ascontiguousarray(displacements),
        np.ascontiguousarray(extra),
        compliance,
        soft,
        np.zeros(0) if stiff is None else stiff,
        scale,
        np.zeros(0) if surface is None else np.ascontiguousarray(surface),
        ratio,
        friction,
        speed,
        indentation,
        depth,
        *biphase_limits(parameters),
        math.nan if tear is None else tear,
        forces,
        shifts,
        torn,
    )
    return forces, share, now, shifts, tuple(torn[:count].tolist())


def spd(rng, n, size):
    a = rng.normal(size=(n, n))
    return np.ascontiguousarray(size * (a @ a.T + n * np.eye(n)))


@settings(max_examples=300, deadline=None)
@given(
    m=st.integers(1, 4),
    seed=st.integers(0, 2**32 - 1),
    surface=st.booleans(),
    passage=st.booleans(),
    phases=st.sampled_from(["one", "scaled", "own"]),
    speed=st.one_of(st.floats(-0.01, 0.05), st.just(0.0)),
    indentation=st.floats(0.0, 2e-3),
    tears=st.booleans(),
)
def test_the_compiled_contact_law_equals_the_numpy_reference(
    m, seed, surface, passage, phases, speed, indentation, tears
):
    rng = np.random.default_rng(seed)
    soft = spd(rng, 3 * m, 100.0)
    law = (
        np.ascontiguousarray(np.linalg.inv(soft)),
        soft,
        spd(rng, 3 * m, 400.0) if phases == "own" else None,
        20.0 if phases == "scaled" else 1.0,
        None if phases == "one" else BiphaseParameters(300e3, 6e6, 0.45, 0.12, 0.1, 0.25, 2.0),
        float(rng.uniform(5e-4, 3e-3)),
        float(rng.uniform(0.5, 1.0)),
        float(rng.uniform(0.0, 1.0)),
        float(rng.uniform(0.05, 2.0)) if tears else None,
    )
    displacements = rng.normal(size=(m, 3)) * 3e-4
    extra = rng.normal(size=(m, 3)) * 0.1 if passage else np.zeros((m, 3))
    normals = rng.normal(size=(m, 3))
    normals = normals / np.linalg.norm(normals, axis=1)[:, None] if surface else None
    expected = reference_step(law, displacements, extra, speed, indentation, normals)
    got = compiled_step(law, displacements, extra, speed, indentation, normals)
    for value, wanted in zip(got, expected, strict=True):
        np.testing.assert_allclose(value, wanted, rtol=1e-12, atol=1e-300)


def test_kernel_step_on_a_real_kernel_set_equals_the_reference():
    """Two kernels on a box's top face in a biphase tissue: the runtime's kernel_step (what the FEM
    step and the recorded sessions' re-derivation call) equals the NumPy law on the load's matrices,
    pressing, sliding and torn."""
    from sim.fem import BiphaseTissue
    from sim.mesh import box_mesh

    mesh = box_mesh(0.01, 10)
    tissue = BiphaseTissue.build(mesh, mesh.node_sets["z0"], BiphaseParameters(300e3, 6e6, 0.45, 0.12))
    points = [(0.004, 0.005, 0.01), (0.006, 0.005, 0.01)]

    def make(model):
        kernels = [kernel_at(model, p, (0, 0, 1), 1e-3) for p in points]
        return kernels, [np.zeros((3, 3))] * 2

    load = KernelLoad(tissue, make)
    forces = NeedleForces(tear_force=0.05, friction_coefficient=0.3)
    stiff = None if load._stiff is None else load._stiff.stiffness
    law = (
        load.soft.compliance,
        load.soft.stiffness,
        stiff,
        load._stiff_scale,
        load.parameters,
        load.depth,
        0.71,
        forces.friction_coefficient,
        forces.tear_force,
    )
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    for depth, sideways, speed in ((1e-4, 0.0, 0.0), (3e-4, 2e-4, 0.004), (2e-3, 0.0, 0.05)):
        d = np.array([[sideways, 0.0, -depth], [0.0, sideways, -depth]])
        step = kernel_step(load, d, np.zeros((2, 3)), speed, 0.0, forces, normals, 0.71)
        expected = reference_step(law, d, np.zeros((2, 3)), speed, 0.0, normals)
        got = (step.kernel_forces, step.share, step.indentation, step.shifts, step.torn)
        for value, wanted in zip(got, expected, strict=True):
            np.testing.assert_allclose(value, wanted, rtol=1e-12, atol=1e-300)
    assert step.torn == (0, 1) and step.share < 1.0  # the deepest press tore both and met the stiff phase
    # the step's drive, worked out when the graphics layer reads it, is the eager one, kept from the
    # forces as they were (the FEM step may reuse its array)
    kernel_forces = step.kernel_forces.copy()
    drive = load.drive(step.kernel_forces, step.share)
    step.kernel_forces[:] = 0.0
    nodes, intended = drive
    assert nodes is load.nodes and len(drive) == 2 and drive[0] is nodes
    np.testing.assert_array_equal(intended, load.kernel_drive(kernel_forces, step.share))
    assert drive.intended is intended  # worked out once


def test_the_compiled_law_refuses_what_does_not_fit():
    law = (np.eye(3), np.eye(3), None, 1.0, None, 1e-3, 1.0, 0.3, None)
    good = np.zeros((1, 3))
    assert compiled_step(law, good, good, 0.0, 0.0, None)[1:3] == (1.0, 0.0)
    with pytest.raises(ValueError, match=r"compliance, soft and stiff .* must be \(6, 6\)"):
        compiled_step(law, np.zeros((2, 3)), np.zeros((2, 3)), 0.0, 0.0, None)
    with pytest.raises(ValueError, match=r"normals must be \(1, 3\) or empty"):
        compiled_step(law, good, good, 0.0, 0.0, np.zeros((2, 3)))
    with pytest.raises(TypeError, match="displacements must be float64"):
        compiled_step(law, good.astype(np.float32), good, 0.0, 0.0, None)
    biphase = (*law[:4], BiphaseParameters(), *law[5:])
    with pytest.raises(ValueError, match="needle_speed must be a non-negative number of m/s; got nan"):
        compiled_step(biphase, np.full((1, 3), 1e-3), good, math.nan, 0.0, None)
    # the same refusal from the runtime's kernel_step is the model's error, as strain_limit_at's was
    from sim.mesh import box_mesh

    mesh = box_mesh(0.01, 6)
    from sim.fem import BiphaseTissue

    tissue = BiphaseTissue.build(mesh, mesh.node_sets["z0"], BiphaseParameters(300e3, 6e6, 0.45, 0.12))
    load = KernelLoad(
        tissue, lambda model: ([kernel_at(model, (0.005, 0.005, 0.01), (0, 0, 1), 2e-3)], [np.zeros((3, 3))])
    )
    with pytest.raises(ModelError, match="needle_speed must be a non-negative number"):
        kernel_step(load, np.full((1, 3), -1e-3), good, math.nan, 0.0, NeedleForces())
