"""How the needle loads the tissue and what resists it: every parameter of the needle's forces in one place.

Before puncture the tissue answers elastically (its stiffness through the force kernel of
:mod:`sim.fem.kernel`, or the paper's barycentric rule for reproduction). The needle pierces
when the normal force reaches ``puncture_force`` at an acceptable angle, and the force drops:
Okamura, Simone and O'Leary (2004, IEEE Trans Biomed Eng 51:1707) split needle insertion
forces into this stiffness phase, then cutting at the tip and friction along the shaft. After
piercing the axial force along the needle's tangent is

    cutting_force                         while the tip advances into uncut wall
  + emergence ramp                        over the last ``emergence_ramp`` of the wall, rising to
                                          ``emergence_force`` as the tip tents the far surface
  + friction_per_length x L x sat(v / stick_speed) + viscous_coefficient x v

with L the length of needle inside the wall and v the tip's speed along the needle: a
Karnopp-style stick band (below ``stick_speed`` the friction grows linearly with speed instead
of jumping to its Coulomb value, the usual regularisation for a needle whose motion is driven
by the hand, not by the force) and a small viscous term (Frick et al. 2001, J Biomech 34:1335,
found no effect of penetration speed between 1 and 10 mm/s). The tip's exit through the far
surface ends the ramp: the emergence peak, Frick's second peak.

Sideways the wall holds the needle where it crosses it: the crossing point's offset from the
entry (and exit) point loads the wall through a force kernel there, so levering the needle
instead of turning it along its curve loads the wall.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from sim.errors import VascsimError

LOAD_MODELS = ("kernel", "barycentric")


class NeedleForcesError(VascsimError, ValueError):
    """A needle-force parameter is out of range."""


@dataclass(frozen=True)
class NeedleForces:
    """Parameters of the needle's load on the tissue, puncture and passage (SI units).

    load: ``"kernel"`` (mesh-independent force kernel with the needle's near field, the default) or
        ``"barycentric"`` (the paper's rule: the contact triangle's nodes driven by their
        barycentric weights; its stiffness scales with element size).
    kernel_radius: radius r (m) of the force kernel; at least 2-3 elements should span it and it
        should not exceed 2/3 of the wall thickness.
    near_field: add the wire's flat-punch near field the kernel cannot resolve.
    lateral_scale: factor on the sideways (levering) stiffness of a pierced wall (1: the kernel's
        own stiffness with the wire's near field in the plane across the needle).
    puncture_force: normal force (N) at which a well-aligned needle pierces; ``None`` uses the
        paper's stress rule (:attr:`sim.needle.interaction.PiercingRules.puncture_stress` x wire area).
    emergence_force: the far wall's resistance (N) just before the tip comes out (Frick's second peak).
    emergence_ramp: depth (m) before the far surface over which that resistance builds.
    cutting_force: axial resistance (N) at the tip while it cuts new wall.
    friction_per_length: Coulomb friction (N/m) per metre of needle inside the wall.
    stick_speed: speed (m/s) below which friction is in its stick band.
    viscous_coefficient: viscous friction (N s/m) along the needle.
    damage_stress: local von Mises stress (Pa) whose first crossing is an ``overstress`` event
        (None: no events); a relative measure of load in this phenomenological model.
    friction_coefficient: Coulomb coefficient between the needle and the wall's surface: a needle
        pressing on the wall sticks until its sideways force reaches this times its normal force,
        then slides.
    tear_force: the largest force (N) the wall carries at one contact or crossing before it gives
        way (a ``tear`` event; the contact then follows the needle at that force); None: no limit.
    recoil_time: time constant (s) with which the wall pushes a released needle back to where it no
        longer loads the wall sideways (the tissue's damped elastic recoil).
    edge_damage_stress: von Mises stress (Pa) of the wound's cut-face elements whose first crossing
        is an ``edge_overstress`` event (None: no events): a bite too near the edge, or a needle
        levered towards it, tearing the edge.
    """

    load: str = "kernel"
    kernel_radius: float = 1e-3
    near_field: bool = True
    lateral_scale: float = 1.0
    puncture_force: float | None = 0.8
    emergence_force: float = 0.3
    emergence_ramp: float = 3e-4
    cutting_force: float = 0.2
    friction_per_length: float = 80.0
    stick_speed: float = 1e-4
    viscous_coefficient: float = 0.5
    damage_stress: float | None = None
    edge_damage_stress: float | None = None
    recoil_time: float = 0.03
    friction_coefficient: float = 0.3
    tear_force: float | None = None

    def __post_init__(self) -> None:
        if self.load not in LOAD_MODELS:
            raise NeedleForcesError(f"load must be one of {', '.join(LOAD_MODELS)}; got {self.load!r}")
        positive = ("kernel_radius", "stick_speed", "emergence_ramp", "lateral_scale", "recoil_time")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise NeedleForcesError(f"{name} must be a positive number; got {value}")
        for name in (
            "emergence_force",
            "cutting_force",
            "friction_per_length",
            "viscous_coefficient",
            "friction_coefficient",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise NeedleForcesError(f"{name} must be zero or a positive number; got {value}")
        for name in ("damage_stress", "edge_damage_stress", "tear_force"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                unit = "N" if name == "tear_force" else "Pa"
                raise NeedleForcesError(f"{name} must be positive ({unit}) or None; got {value}")
        if self.puncture_force is not None and not (
            math.isfinite(self.puncture_force) and self.puncture_force > 0
        ):
            raise NeedleForcesError(f"puncture_force must be positive (N) or None; got {self.puncture_force}")

    @classmethod
    def paper(cls) -> NeedleForces:
        """The source paper's needle: barycentric load, the stress rule, no passage forces."""
        return cls(
            load="barycentric",
            puncture_force=None,
            emergence_force=0.0,
            cutting_force=0.0,
            friction_per_length=0.0,
            viscous_coefficient=0.0,
        )

    def as_dict(self) -> dict[str, object]:
        """The parameters as plain JSON values (a session's header records the law it ran under)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> NeedleForces:
        """Parameters from :meth:`as_dict`'s form, checked: unknown names and bad values are errors."""
        if not isinstance(values, dict):
            raise NeedleForcesError(
                f"needle forces must be a mapping of parameter names; got {type(values).__name__}"
            )
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise NeedleForcesError(f"unknown needle-force parameter(s): {', '.join(map(str, unknown))}")
        try:
            return cls(**values)
        except TypeError as error:
            raise NeedleForcesError(f"needle-force parameters of the wrong type: {error}") from error

    def with_(self, **changes: object) -> NeedleForces:
        """A copy with some parameters changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @property
    def resists_passage(self) -> bool:
        """Whether any axial force acts on a needle in the wall."""
        return any(
            (self.cutting_force, self.friction_per_length, self.viscous_coefficient, self.emergence_force)
        )

    def axial_resistance(
        self, speed: float, inside_length: float, cutting: bool, emergence_depth: float
    ) -> float:
        """The wall's resistance (N) along the needle against its motion: positive opposes a forward
        (tip-first) motion at ``speed`` (m/s, signed along the needle's tangent).

        inside_length: needle length in the wall (m); cutting: the tip is advancing into uncut wall;
        emergence_depth: how far (m) the tip is into the emergence ramp (0 before it).
        """
        band = max(-1.0, min(1.0, speed / self.stick_speed))
        friction = self.friction_per_length * inside_length * band + self.viscous_coefficient * speed
        cut = self.cutting_force * max(band, 0.0) if cutting else 0.0
        rise = min(max(emergence_depth / self.emergence_ramp, 0.0), 1.0)
        return friction + cut + self.emergence_force * rise
