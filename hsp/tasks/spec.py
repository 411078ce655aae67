"""The task file schema (``pipeline/tasks/<task>.yaml``), validated with pydantic.

A task says which objects take part (index 0 is the end-effector), how a random layout
is drawn, what success means (paper, Section V-C) and how the scripted demonstrator moves.
Lengths in metres, angles in radians unless a field name says otherwise.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, model_validator

Range = tuple[float, float]
Vec3 = tuple[float, float, float]
Symmetry = Literal["none", "x_2fold", "z_continuous", "z_2fold", "z_4fold", "z_6fold", "cube"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Placement(_Strict):
    """Where an object starts. ``support: table`` samples x, y, yaw in the ranges and rests
    the object on the table; ``support: <object>`` puts it at ``xyz`` in that object's
    frame; the end-effector (``support: air``) starts at a sampled x, y, z, yaw."""

    support: str = "table"
    x: Range = (0.0, 0.0)
    y: Range = (0.0, 0.0)
    z: Range = (0.0, 0.0)
    yaw: Range = (-3.141592653589793, 3.141592653589793)
    xyz: Vec3 = (0.0, 0.0, 0.0)
    fixed: bool = False
    """The object never moves (a wheel bolted to its hub)."""
    joint: Literal["none", "revolute_z"] = "none"
    """``revolute_z``: the object turns about its own z axis on a fixed mount (lug nuts)."""

    @model_validator(mode="after")
    def _ranges_ordered(self) -> "Placement":
        for key in ("x", "y", "z", "yaw"):
            lo, hi = getattr(self, key)
            if lo > hi:
                raise ValueError(f"place.{key}: lower bound {lo} > upper bound {hi}")
        return self


class ObjectSpec(_Strict):
    name: str = Field(pattern=r"^[a-z][a-z0-9_]*$")
    label: str
    """Semantic class l^i; identical objects (the four bolts) share one label."""
    model: str
    """URDF file in ``pipeline/objects`` (simulator)."""
    mesh: str
    """OBJ file in ``pipeline/objects`` (tracker and renderer)."""
    symmetry: Symmetry = "none"
    keypoints: dict[str, Vec3] = {}
    """Named points in the object frame (brush tip, paint centre, bolt socket…)."""
    place: Placement = Placement()


class PaintingSuccess(_Strict):
    """Brush tip within ``source_radius`` of the paint centre, then on the plane
    ``plane_height`` above the canvas, then a straight stroke ≥ ``stroke_length`` there."""

    kind: Literal["painting"]
    tool: str
    tool_point: str
    source: str
    source_point: str
    surface: str
    surface_point: str
    source_radius: float = Field(0.03, gt=0)
    plane_height: float = Field(0.10, gt=0)
    plane_tolerance: float = Field(0.01, gt=0)
    stroke_length: float = Field(0.05, gt=0)
    stroke_straightness: float = Field(0.9, gt=0, le=1)
    """Chord over path length of the stroke; 1 is perfectly straight."""
    surface_half_extent: tuple[float, float] | None = None
    """If set, the stroke must lie over the canvas (half sizes in x, y of its frame)."""


class StackingSuccess(_Strict):
    """Every block centre within ``tolerance`` of its place in the pattern, expressed in
    the frame of the ``base`` block (up to the base's symmetry)."""

    kind: Literal["stacking"]
    base: str
    pattern: dict[str, Vec3]
    tolerance: float = Field(0.005, gt=0)


class TireRemovalSuccess(_Strict):
    """For every bolt: the tool point within ``tolerance`` of the bolt's socket point while
    the bolt turns ≥ ``min_rotation_deg`` counter-clockwise (seen from above); after
    the last bolt, the tool point within ``tolerance`` of the wheel centre."""

    kind: Literal["tire_removal"]
    tool: str
    tool_point: str
    bolts: list[str]
    bolt_point: str
    wheel: str
    wheel_point: str
    tolerance: float = Field(0.005, gt=0)
    min_rotation_deg: float = Field(30.0, gt=0)


SuccessSpec = Annotated[Union[PaintingSuccess, StackingSuccess, TireRemovalSuccess], Field(discriminator="kind")]


class DemonstratorSpec(_Strict):
    """How the scripted demonstrator moves: minimum-jerk segments with human variation."""

    embodiment: Literal["hand", "kuka"]
    speed: float = Field(0.25, gt=0)
    """Mean Cartesian speed of a segment (m/s); durations are drawn around dist/speed."""
    min_duration: float = Field(0.6, gt=0)
    duration_jitter: Range = (0.8, 1.3)
    pause: Range = (0.1, 0.5)
    """Still time after a segment (s)."""
    tremor: float = Field(0.0008, ge=0)
    """Amplitude of the 8–12 Hz positional tremor (m)."""
    curve: float = Field(0.03, ge=0)
    """Largest sideways/upward bulge of an approach path (m)."""
    approach_height: float = Field(0.08, gt=0)
    grasp_offset: float = Field(0.02, ge=0)
    """Largest shift of the grasp point along the graspable axis (m)."""
    lift_height: float = Field(0.12, gt=0)
    rotation_deg: Range = (40.0, 60.0)
    """Tire removal: how far each bolt is turned (degrees, counter-clockwise)."""


class TaskSpec(_Strict):
    name: str
    description: str = ""
    kind: Literal["painting", "stacking", "tire_removal"]
    objects: list[ObjectSpec] = Field(min_length=2)
    min_clearance: float = Field(0.03, ge=0)
    """Free space kept between footprints of table objects in a random layout (m)."""
    success: SuccessSpec
    demonstrator: DemonstratorSpec

    @model_validator(mode="after")
    def _names_resolve(self) -> "TaskSpec":
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ValueError(f"objects: duplicate names in {names}")
        for i, o in enumerate(self.objects[1:], start=1):
            if o.place.support not in ("table", *names[:i]):
                raise ValueError(f"objects.{i}.place.support: {o.place.support!r} is neither 'table' nor an object listed before {o.name!r}")
        referenced = [v for k, v in self.success.model_dump().items() if k in ("tool", "source", "surface", "base", "wheel")]
        referenced += list(getattr(self.success, "pattern", {}).keys()) + list(getattr(self.success, "bolts", []))
        for name in referenced:
            if name not in names:
                raise ValueError(f"success: object {name!r} is not in objects {names}")
        return self
