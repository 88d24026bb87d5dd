"""The one exception hierarchy of vascsim.

Every error the project raises on purpose derives from :class:`VascsimError`, so
callers (the CLI, the dashboard) can catch it in one place and show its message,
which always names the input that was wrong. Higher packages subclass it.
"""


class VascsimError(Exception):
    """Base class of every error vascsim raises on purpose.

    ``remedy`` names what would put it right as (action, subject), e.g. ("recover", "S-1a2b"),
    ("score", "course"): the message itself carries no front-end's advice, and each front-end says
    the remedy in its own words (the CLI as the command to run)."""

    def __init__(self, *args: object, remedy: tuple[str, str] | None = None) -> None:
        super().__init__(*args)
        self.remedy = remedy


class MeshError(VascsimError, ValueError):
    """A mesh is malformed: bad coordinates, indices, orientation or surface."""


class MaterialError(VascsimError, ValueError):
    """A material parameter is out of its physical range."""


class ModelError(VascsimError, ValueError):
    """A tissue model was configured or queried with inconsistent input."""


class SolverError(VascsimError, RuntimeError):
    """A numerical solve failed (e.g. the penalised stiffness is not positive definite)."""


class CacheError(VascsimError):
    """A cached precomputation is missing, corrupted or does not match its key."""


class VascsimWarning(UserWarning):
    """Base class of vascsim's warnings (e.g. Poisson's ratio above the paper's stable limit)."""


class TrackingError(VascsimError, ValueError):
    """A camera, its calibration, an instrument's markers or a video source failed or was refused."""
