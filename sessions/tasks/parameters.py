"""A task's parameters, typed by its kind: what each kind of task is built from, read and checked by
name (never a dict looked into by string), and stored as the JSON the catalog and the model cache key
hold (:meth:`TaskParameters.as_dict`).

- :class:`WallPatchParameters` (``wall_patch``), :class:`VesselPatchParameters` (``vessel_patch``),
  :class:`MeshFileParameters` (``mesh_file``: a task added from a mesh; its file, ``task.json``,
  can be edited by hand, so :func:`parameters_from` checks every field before anything is built).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from typing import Any, ClassVar

from sim.calibration.presets import PRESETS
from sim.errors import VascsimError

MODELS = ("biphase",)
"""Tissue models a task can name (the penalty-condensed biphase wall)."""
_SET_NAME = re.compile(r"[A-Za-z0-9_-]{1,40}")
_FILE_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]{0,80}")


@dataclass(frozen=True)
class TaskParameters:
    """What every kind of task names: the mesh's node sets held fixed, the tissue model and preset,
    and the presets of regions that differ from the wall (mesh region name -> preset)."""

    scenario: ClassVar[str]
    fixed: tuple[str, ...]
    model: str = "biphase"
    tissue: str = "paper"
    region_tissue: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The stored form (JSON-ready; optional fields left out when unset, as tasks were stored)."""
        stored = {}
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if value is None or (item.name == "region_tissue" and not value):
                continue
            stored[item.name] = _plain(value)
        return stored


@dataclass(frozen=True)
class WallPatchParameters(TaskParameters):
    """A flat block of wall: its size (x, y, thickness; m), the coarse cell and the stitch region's
    finer cell (m), and the stitch region ((x0, x1), (y0, y1); m)."""

    scenario: ClassVar[str] = "wall_patch"
    size_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cell_m: float = 0.0
    stitch_cell_m: float = 0.0
    stitch_region_m: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 0.0), (0.0, 0.0))


@dataclass(frozen=True)
class WoundCut:
    """An arteriotomy along the vessel: at ``angle_deg``, from ``z_m[0]`` to ``z_m[1]`` (m), gaping
    ``gap_m`` at mid-length."""

    angle_deg: float
    z_m: tuple[float, float]
    gap_m: float


@dataclass(frozen=True)
class Plaque:
    """A calcified plaque: an angle range (deg), a z range (m) and the radial layers it fills."""

    angle_deg: tuple[float, float]
    z_m: tuple[float, float]
    layers: tuple[int, ...]


@dataclass(frozen=True)
class ArcRegion:
    """A region of a vessel's outer surface: an angle range (deg) and a z range (m)."""

    angle_deg: tuple[float, float]
    z_m: tuple[float, float]


@dataclass(frozen=True)
class VesselPatchParameters(TaskParameters):
    """An arc of an artery's wall: its radius, thickness and length (m), the arc (deg), the
    (circumferential, radial, axial) divisions, the arteriotomy, the stitch region and a plaque
    where the task has one."""

    scenario: ClassVar[str] = "vessel_patch"
    inner_radius_m: float = 0.0
    wall_m: float = 0.0
    length_m: float = 0.0
    arc_deg: float = 0.0
    divisions: tuple[int, int, int] = (0, 0, 0)
    wound: WoundCut = WoundCut(0.0, (0.0, 0.0), 0.0)
    stitch_region: ArcRegion = ArcRegion((0.0, 0.0), (0.0, 0.0))
    calcification: Plaque | None = None


@dataclass(frozen=True)
class MeshFileParameters(TaskParameters):
    """A wall meshed elsewhere: its file in the task's folder, and the radius about the entry (m)
    whose outer-surface nodes are the contact candidates."""

    scenario: ClassVar[str] = "mesh_file"
    mesh_file: str = "mesh.vtu"
    stitch_radius_m: float = 0.003


KIND_PARAMETERS: dict[str, type[TaskParameters]] = {
    kind.scenario: kind for kind in (WallPatchParameters, VesselPatchParameters, MeshFileParameters)
}


def _plain(value: Any) -> Any:
    """Tuples as lists and nested records as dicts: the JSON form."""
    if dataclasses.is_dataclass(value):
        return {item.name: _plain(getattr(value, item.name)) for item in dataclasses.fields(value)}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


# -- reading the stored form, every field checked ---------------------------------------------------
class _Reader:
    """Reads one stored mapping's fields, refusing (VascsimError naming ``where`` and the field) any
    that is missing, of the wrong type or out of range, and any field it does not know."""

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, dict):
            raise VascsimError(f"{where} must be an object, not {type(data).__name__}")
        self.data, self.where, self.read = data, where, set()

    def raw(self, name: str, default: Any = dataclasses.MISSING) -> Any:
        """The field as stored (marked read), ``default`` when absent, or refused when required."""
        self.read.add(name)
        if name not in self.data:
            if default is dataclasses.MISSING:
                raise VascsimError(f"{self.where} has no {name!r}")
            return default
        return self.data[name]

    def number(self, name: str, low: float, high: float, default: Any = dataclasses.MISSING) -> float:
        value = self.raw(name, default)
        return self._number(value, name, low, high)

    def _number(self, value: Any, name: str, low: float, high: float) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise VascsimError(f"{self.where}: {name} must be a number, not {value!r}")
        if not low <= value <= high:
            raise VascsimError(f"{self.where}: {name} {value!r} is outside {low:g} to {high:g}")
        return float(value)

    def numbers(
        self, name: str, count: int, low: float, high: float, value: Any = dataclasses.MISSING
    ) -> tuple:
        value = self.raw(name) if value is dataclasses.MISSING else value
        if not isinstance(value, list) or len(value) != count:
            raise VascsimError(f"{self.where}: {name} must be a list of {count} numbers, not {value!r}")
        return tuple(self._number(v, name, low, high) for v in value)

    def span(self, name: str, low: float, high: float) -> tuple[float, float]:
        start, stop = self.numbers(name, 2, low, high)
        if start >= stop:
            raise VascsimError(f"{self.where}: {name} must run from low to high, not {[start, stop]}")
        return start, stop

    def integers(self, name: str, count: int | None, low: int, high: int) -> tuple[int, ...]:
        value = self.raw(name)
        if not isinstance(value, list) or (count is not None and len(value) != count) or not value:
            raise VascsimError(f"{self.where}: {name} must be a list of whole numbers, not {value!r}")
        if not all(type(v) is int and low <= v <= high for v in value):
            raise VascsimError(f"{self.where}: {name} must hold whole numbers {low}-{high}, not {value!r}")
        return tuple(value)

    def text(
        self, name: str, choices: tuple[str, ...] | None = None, default: Any = dataclasses.MISSING
    ) -> str:
        value = self.raw(name, default)
        if not isinstance(value, str) or (choices is not None and value not in choices):
            listed = f"one of {', '.join(choices)}" if choices is not None else "text"
            raise VascsimError(f"{self.where}: {name} must be {listed}, not {value!r}")
        return value

    def names(self, name: str) -> tuple[str, ...]:
        value = self.raw(name)
        if not isinstance(value, list) or not value:
            raise VascsimError(f"{self.where}: {name} must be a list of node set names, not {value!r}")
        for item in value:
            if not isinstance(item, str) or not _SET_NAME.fullmatch(item):
                raise VascsimError(f"{self.where}: {name} holds {item!r}, not a node set name")
        return tuple(value)

    def presets(self, name: str) -> dict[str, str]:
        value = self.raw(name, {})
        if not isinstance(value, dict):
            raise VascsimError(f"{self.where}: {name} must map region names to presets, not {value!r}")
        for region, preset in value.items():
            if not (_SET_NAME.fullmatch(region) and isinstance(preset, str) and preset in PRESETS):
                raise VascsimError(
                    f"{self.where}: {name} maps {region!r} to {preset!r}; presets are {', '.join(PRESETS)}"
                )
        return dict(value)

    def nested(self, name: str, optional: bool = False) -> _Reader | None:
        value = self.raw(name, None if optional else dataclasses.MISSING)
        return None if value is None else _Reader(value, f"{self.where}: {name}")

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.read)
        if unknown:
            raise VascsimError(f"{self.where} has fields it cannot use: {', '.join(map(repr, unknown))}")


def parameters_from(scenario: str, data: Any, where: str) -> TaskParameters:
    """The typed parameters of a ``scenario`` task from their stored form ``data``: every field checked
    (types, finite numbers in physical ranges, known presets, node set and file names that are names,
    nothing unknown); VascsimError naming ``where`` and the field otherwise."""
    if scenario not in KIND_PARAMETERS:
        raise VascsimError(f"{where}: scenario {scenario!r} is not one of {', '.join(KIND_PARAMETERS)}")
    read = _Reader(data, where)
    common = {
        "fixed": read.names("fixed"),
        "model": read.text("model", MODELS, "biphase"),
        "tissue": read.text("tissue", tuple(PRESETS), "paper"),
        "region_tissue": read.presets("region_tissue"),
    }
    if scenario == "wall_patch":
        region = read.raw("stitch_region_m")
        if not isinstance(region, list) or len(region) != 2:
            raise VascsimError(f"{where}: stitch_region_m must be [[x0, x1], [y0, y1]], not {region!r}")
        made: TaskParameters = WallPatchParameters(
            **common,
            size_m=read.numbers("size_m", 3, 1e-4, 1.0),
            cell_m=read.number("cell_m", 1e-5, 0.1),
            stitch_cell_m=read.number("stitch_cell_m", 1e-5, 0.1),
            stitch_region_m=tuple(read.numbers("stitch_region_m", 2, 0.0, 1.0, span) for span in region),
        )
    elif scenario == "vessel_patch":
        wound, stitch = read.nested("wound"), read.nested("stitch_region")
        plaque = read.nested("calcification", optional=True)
        made = VesselPatchParameters(
            **common,
            inner_radius_m=read.number("inner_radius_m", 1e-4, 0.1),
            wall_m=read.number("wall_m", 1e-5, 0.05),
            length_m=read.number("length_m", 1e-4, 1.0),
            arc_deg=read.number("arc_deg", 1.0, 360.0),
            divisions=read.integers("divisions", 3, 1, 1000),
            wound=WoundCut(
                wound.number("angle_deg", -360, 360), wound.span("z_m", 0, 1), wound.number("gap_m", 0, 0.01)
            ),
            stitch_region=ArcRegion(stitch.span("angle_deg", -360, 360), stitch.span("z_m", 0, 1)),
            calcification=None
            if plaque is None
            else Plaque(
                plaque.span("angle_deg", -360, 360),
                plaque.span("z_m", 0, 1),
                plaque.integers("layers", None, 0, 1000),
            ),
        )
        for part in (wound, stitch, plaque):
            if part is not None:
                part.finish()
    else:
        mesh_file = read.text("mesh_file")
        if not _FILE_NAME.fullmatch(mesh_file) or mesh_file in (".", ".."):
            raise VascsimError(f"{where}: mesh_file {mesh_file!r} must be a file name in the task's folder")
        made = MeshFileParameters(
            **common, mesh_file=mesh_file, stitch_radius_m=read.number("stitch_radius_m", 1e-5, 1.0)
        )
    read.finish()
    return made
