"""Lane sensor profiles: what a sensor sees and how it errs, as one frozen configuration.

A :class:`SensorProfile` is chosen by name from :data:`BUILTIN_PROFILES` (``ideal``,
``camera``, ``camera-highway``) or read from a TOML file that overrides any field of a
built-in one (:func:`load_profile`). ``ideal`` is the paper's generic sensor: the lane
``r_lane`` ahead along its centreline, never failing, no error. ``camera`` profiles see
only what a windscreen camera sees (``simulation.camera``) and carry the parameters of the
cubic lane-model error (``simulation.lane_model_error``).

TOML file (every key optional; ``base`` names the built-in profile it starts from,
default ``camera``; ``[lane_error]`` sets fields of :class:`LaneModelErrorParams`)::

    base = "camera"
    max_range_m = 70.0
    fov_half_angle_rad = 0.6
    [lane_error]
    sigma_c0_m = 0.1
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Final, Literal, Mapping

from cold_maps.simulation.lane_model_error import LaneModelErrorParams
from cold_maps.simulation.sensor import SENSOR_RANGE_M, SENSOR_STEP_M

SensorKind = Literal["ideal", "camera"]
SENSOR_KINDS: Final[tuple[str, ...]] = ("ideal", "camera")
DEFAULT_PROFILE: Final[str] = "ideal"
MAX_SENSOR_RANGE_M: Final[float] = 1000.0
"""Longest sensor range a profile accepts (m)."""


@dataclass(frozen=True)
class SensorProfile:
    """One lane sensor. Vehicle frame ISO 8855 (x forward, y left), camera at the vehicle's
    pose on its lane centreline. Fields the ideal kind ignores are marked (camera).

    Fields:
        name: the profile's name (a built-in name or the TOML file's stem), for provenance.
        kind: ``ideal`` (the paper's sensor: the lane ``max_range_m`` ahead along the
            centreline, never failing) or ``camera`` (visibility rules of
            ``simulation.camera``).
        min_range_m: (camera) nearest detected border point, plane distance from the
            camera (m). 3 m: issue 26's starting value; assumption (the bonnet hides the
            road just ahead of a windscreen camera).
        max_range_m: farthest detected border point (m): plane distance from the camera
            (camera), centreline length ahead (ideal; the paper's r_lane = 30 m).
            Camera 50 m urban, 100 m highway: issue 26's starting values; 100 m is the
            range OpenLane's and the Apollo synthetic set's 3-D lanes are evaluated to
            (PersFormer, Chen et al., ECCV 2022); urban 50 m is an assumption.
        fov_half_angle_rad: (camera) horizontal half field of view (rad): a point is seen
            when the angle between the heading and the line of sight is at most this.
            25° (50° full): issue 26's starting value; assumption (front lane cameras
            have horizontal fields of view of about 50° to 100°).
        camera_height_m: (camera) camera height above the road at the vehicle (m).
            1.3 m: issue 26's starting value; assumption (a passenger car's windscreen;
            KITTI's roof cameras are at 1.65 m).
        vehicle_length_m, vehicle_width_m: (camera) footprint of every other vehicle of
            the drive, centred on its pose (m). 4.5 × 1.8 m: issue 26's starting values;
            assumption (a mid-size passenger car). Vehicles are taken as taller than the
            camera: a footprint hides whatever lies behind it in the plane.
        gap_tolerance_m: (camera) a border hidden over at most this length along it (m)
            does not end the detection (a tracker bridges it); a longer gap does.
            12 m: assumption, the longest gap of a dashed line (German motorway guide
            line: 6 m dash, 12 m gap, RMS). Dashed marks are detectable over their whole
            length (``opendrive.road_marks``), so dashes never end a detection.
        step_m: spacing of the reported border points along each border (m); 0.10 m as
            the paper's sensor.
        lane_error: (camera) the cubic lane-model error (``lane_model_error``; all zero
            for ideal). Camera: σ(c0) 0.05 m, σ(c1) 2 mrad, σ(c2) 4e-5 1/m, σ(c3) 0,
            white 0.01 m, τ 0.5 s: issue 26's starting values; assumption, of the order
            of the near-range lateral errors of camera 3-D lane detectors (0.02–0.07 m
            within 40 m on the Apollo synthetic set, PersFormer and LATR).
    """

    name: str = DEFAULT_PROFILE
    kind: SensorKind = "ideal"
    min_range_m: float = 0.0
    max_range_m: float = SENSOR_RANGE_M
    fov_half_angle_rad: float = math.pi
    camera_height_m: float = 1.3
    vehicle_length_m: float = 4.5
    vehicle_width_m: float = 1.8
    gap_tolerance_m: float = 12.0
    step_m: float = SENSOR_STEP_M
    lane_error: LaneModelErrorParams = field(default_factory=LaneModelErrorParams)

    def __post_init__(self) -> None:
        if self.kind not in SENSOR_KINDS:
            raise ValueError(f"sensor profile {self.name}: kind must be one of {', '.join(SENSOR_KINDS)}, "
                             f"got {self.kind!r}")
        _check(self, "max_range_m", 0.0, MAX_SENSOR_RANGE_M, low_open=True)
        _check(self, "min_range_m", 0.0, self.max_range_m, high_open=True)
        _check(self, "fov_half_angle_rad", 0.0, math.pi, low_open=True)
        _check(self, "camera_height_m", 0.0, 100.0, low_open=True)
        _check(self, "vehicle_length_m", 0.0, 100.0)
        _check(self, "vehicle_width_m", 0.0, 100.0)
        _check(self, "gap_tolerance_m", 0.0, MAX_SENSOR_RANGE_M)
        _check(self, "step_m", 0.0, self.max_range_m, low_open=True)
        if not isinstance(self.lane_error, LaneModelErrorParams):
            raise ValueError(f"sensor profile {self.name}: lane_error must be LaneModelErrorParams")

    def describe(self) -> str:
        """One line listing every parameter (units in the names), for provenance."""
        own = ", ".join(f"{f.name} {getattr(self, f.name):g}" for f in fields(self)
                        if f.name not in ("name", "kind", "lane_error"))
        error = ", ".join(f"{f.name} {getattr(self.lane_error, f.name):g}" for f in fields(self.lane_error))
        return f"sensor {self.name} ({self.kind}): {own}; lane_error: {error}"


def _check(profile: SensorProfile, name: str, low: float, high: float, *, low_open: bool = False,
           high_open: bool = False) -> None:
    """ValueError naming the field when it is not a finite number in the interval."""
    value = getattr(profile, name)
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
          and (low < value if low_open else low <= value) and (value < high if high_open else value <= high))
    if not ok:
        bounds = f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        raise ValueError(f"sensor profile {profile.name}: {name} must be a number in {bounds}, got {value!r}")


IDEAL: Final[SensorProfile] = SensorProfile()
CAMERA: Final[SensorProfile] = SensorProfile(
    name="camera", kind="camera", min_range_m=3.0, max_range_m=50.0, fov_half_angle_rad=math.radians(25.0),
    lane_error=LaneModelErrorParams(sigma_c0_m=0.05, sigma_c1_rad=0.002, sigma_c2_per_m=4e-5, sigma_c3_per_m2=0.0,
                                    white_m=0.01, tau_s=0.5))
CAMERA_HIGHWAY: Final[SensorProfile] = replace(CAMERA, name="camera-highway", max_range_m=100.0)
BUILTIN_PROFILES: Final[Mapping[str, SensorProfile]] = {p.name: p for p in (IDEAL, CAMERA, CAMERA_HIGHWAY)}


def load_profile(text: str) -> SensorProfile:
    """The built-in profile named ``text`` or the profile of the TOML file ``text``
    (``*.toml``); ValueError in one line naming the file and the key otherwise."""
    if text in BUILTIN_PROFILES:
        return BUILTIN_PROFILES[text]
    if not text.endswith(".toml"):
        raise ValueError(f"unknown sensor {text!r}: expected one of {', '.join(BUILTIN_PROFILES)} or a FILE.toml")
    import tomllib

    path = Path(text)
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not TOML: {exc}") from None
    try:
        return profile_from_mapping(document, path.stem)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def profile_from_mapping(document: Mapping[str, Any], name: str) -> SensorProfile:
    """A profile named ``name`` from a mapping (a parsed TOML file, see the module);
    ValueError naming the key that is unknown or has a bad value."""
    values = dict(document)
    base_name = values.pop("base", "camera")
    if base_name not in BUILTIN_PROFILES:
        raise ValueError(f"base: expected one of {', '.join(BUILTIN_PROFILES)}, got {base_name!r}")
    base = BUILTIN_PROFILES[base_name]
    known = {f.name for f in fields(SensorProfile)} - {"name", "lane_error"}
    error_values = values.pop("lane_error", {})
    if not isinstance(error_values, Mapping):
        raise ValueError("lane_error: expected a table of lane-model error parameters")
    error_known = {f.name for f in fields(LaneModelErrorParams)}
    for key in values:
        if key not in known:
            raise ValueError(f"unknown key {key!r} (known: base, {', '.join(sorted(known))}, [lane_error])")
    for key in error_values:
        if key not in error_known:
            raise ValueError(f"unknown key lane_error.{key} (known: {', '.join(sorted(error_known))})")
    for key, value in [*values.items(), *error_values.items()]:
        if key != "kind" and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ValueError(f"{key}: expected a number, got {value!r}")
    try:
        error = replace(base.lane_error, **{k: float(v) for k, v in error_values.items()})
    except ValueError as exc:
        raise ValueError(str(exc).replace("lane model error: ", "lane_error.")) from None
    numbers = {k: (v if k == "kind" else float(v)) for k, v in values.items()}
    try:
        return replace(base, name=name, lane_error=error, **numbers)
    except ValueError as exc:
        raise ValueError(str(exc).replace(f"sensor profile {name}: ", "")) from None
