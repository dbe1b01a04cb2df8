"""The ``[plant]`` table of a MuJoCo scenario: which robot, which of its parts, what the plant adds.

Plain, validated data (:class:`MujocoConfig`); :func:`mlpfac.plants.mjcf.robot.read_robot` reads the
robot it names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.model_file import is_menagerie, menagerie_name, model_path, shipped_model
from mlpfac.plants.sensors.sensing import check_sensing

LIMITS = ("wheel_radius", "track", "turning_track", "max_wheel_speed", "timestep")
ARMATURE_MAX = 1e3  # kg m^2 on a wheel's hinge, at most
NOISE_STD_MAX = 10.0  # m and rad of pose noise, at most
TIMESTEP_MIN, TIMESTEP_MAX = 1e-5, 0.1  # physics timestep (s): finer would take hours, coarser is not physics


def _positive(name: str, value, optional: bool = False, inf: bool = False) -> None:
    if optional and value is None:
        return
    if inf and value == math.inf:
        return
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        raise ConfigError(name, f"must be a positive number, got {value!r}")


def check_timestep(dt: float | None, where: str, whose: str = "") -> None:
    """A physics timestep (s) inside [TIMESTEP_MIN, TIMESTEP_MAX]; a ConfigError naming ``where`` else."""
    if dt is not None and not TIMESTEP_MIN <= dt <= TIMESTEP_MAX:
        raise ConfigError(
            where,
            f"{whose}{dt:g} s is outside {TIMESTEP_MIN:g} .. {TIMESTEP_MAX:g} s (a finer one would take hours to "
            "simulate, a coarser one is not physics)",
        )


@dataclass(frozen=True)
class MujocoConfig:
    """The robot and its drive. Defaults are the shipped robot (models/README.md)."""

    model: str = field(
        default_factory=shipped_model
    )  # MJCF file (from the scenario's folder) or "menagerie:ROBOT/ENTRY"
    # None below: chosen from the model (mlpfac.plants.mjcf.defaults, docs/robots.md), written into config.toml
    actuator: str | None = None  # "velocity": the model's velocity servos; "torque": torque motors + PI here
    # None below: found in the model (mlpfac.plants.mjcf.detect); frame_offset None is 0 for a frame that is named
    left_actuator: str | None = None  # velocity servo (<velocity kv forcerange>) on the left wheel's hinge
    right_actuator: str | None = None
    left_actuator_2: str | None = None  # a second driven wheel on the left (skid-steer), commanded as the first
    right_actuator_2: str | None = None
    tendon_actuators: tuple[str, str] | None = None  # two motors on tendons over both wheels (a (v, omega) drive)
    site: str | None = None  # the pose frame: a site on the axle midpoint, x forward (not with body)
    body: str | None = None  # ... or a body's frame instead of a site
    frame_offset: tuple[float, float, float] | None = None  # the pose frame moved by this, in its axes (m)
    keyframe: str | None = (
        None  # start from this keyframe of the model (None: "home" if it has one, else its default pose)
    )
    other_actuators: str | None = None  # "hold": keep the keyframe's controls; "lock": fix their joints at the keyframe
    tyre: str | None = None  # "model": the wheels' own collision geoms; "sphere": a sphere tyre on each wheel
    casters: str | None = None  # "model": other floor contacts as modelled; "frictionless": they slide (condim 1)
    servo_limit: str | None = (
        None  # "model": MuJoCo clamps the wheel servos' force; "control": the plant does, each physics step
    )
    timestep: float | None = None  # physics timestep (s); None: the model's
    armature: float | None = None  # rotor inertia on each driven wheel's hinge (kg m^2); None: the model's
    wheel_radius: float | None = None  # radius the IK believes (m); None: read from the model
    track: float | None = None  # wheel separation the IK believes (m); None: read from the model
    turning_track: float | None = None  # a skid-steer's: the track it turns as (m); None: measured as it settles
    max_wheel_speed: float | None = None  # rad/s, kept by scaling (v, omega); None: the model's; inf: none
    pose_noise_std: float | tuple[float, ...] = 0.0  # std of Gaussian noise on (x, y, theta): scalar or 3
    twist_noise_std: float | tuple[float, float] = (
        0.0  # std of noise on the twist a torque-level controller measures: v (m/s), omega (rad/s)
    )
    wheel_speed_noise_std: float = 0.0  # std of noise on the wheel speeds a torque-level controller measures (rad/s)
    pi_kp: float | None = None  # torque drive: PI proportional gain, N m per rad/s; None: scaled to the robot's inertia
    pi_ki: float | None = None  # torque drive: PI integral gain, N m per rad; None: scaled to the robot's inertia
    # --- what the robot senses of its pose (mlpfac.plants.sensors.sensing) ---
    pose_source: str = "truth"  # "truth" (the pose, + pose_noise_std), "odometry" (wheels, gyro), "fused" (+ fixes)
    encoder_cpr: int | None = None  # the wheel encoders' counts a revolution; None: exact angles
    gyro: bool = False  # the heading rate from a gyro on the pose frame (MuJoCo's gyro sensor), not the wheels
    gyro_noise: float = 0.0  # std of white noise on each gyro reading (rad/s)
    gyro_bias: float = 0.0  # constant bias of the gyro (rad/s); a distribution draws it per seed
    fix_rate_hz: float | None = None  # "fused": absolute fixes of the pose a second (None: 10)
    fix_latency_s: float | None = None  # "fused": a fix arrives this long after it was taken (None: 0)
    fix_noise_m: float | None = None  # "fused": std of a fix's position noise (m; None: 0.02)
    fix_noise_rad: float | None = None  # "fused": std of a fix's heading noise (rad; None: 0.02)

    def __post_init__(self) -> None:
        choices = {
            "actuator": ("velocity", "torque"),
            "other_actuators": ("hold", "lock"),
            "tyre": ("model", "sphere"),
            "casters": ("model", "frictionless"),
            "servo_limit": ("model", "control"),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed and getattr(self, name) is not None:
                raise ConfigError(name, f"choose {' or '.join(map(repr, allowed))}, got {getattr(self, name)!r}")
        names = ("model", "left_actuator", "right_actuator", "left_actuator_2", "right_actuator_2", "site", "body")
        for name in (*names, "keyframe"):
            value = getattr(self, name)
            if (value is not None or name == "model") and (not isinstance(value, str) or not value):
                raise ConfigError(name, f"expected a non-empty name, got {value!r}")
        pair = self.tendon_actuators
        if pair is not None and (len(pair) != 2 or not all(isinstance(x, str) and x for x in pair)):
            raise ConfigError("tendon_actuators", f"expected two actuators' names, got {pair!r}")
        if pair is not None and (self.left_actuator or self.right_actuator):
            raise ConfigError(
                "tendon_actuators", "the wheels are driven by wheel actuators or by tendon actuators, not both"
            )
        if self.site is not None and self.body is not None:
            raise ConfigError(
                "body", f"the pose frame is a site or a body, not both (site {self.site!r}, body {self.body!r})"
            )
        off = np.asarray(self.offset, dtype=float)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ConfigError("frame_offset", f"expected three finite numbers (m), got {self.frame_offset!r}")
        for name in LIMITS:
            _positive(name, getattr(self, name), optional=True, inf=name == "max_wheel_speed")
        check_timestep(self.timestep, "timestep")
        arm = self.armature
        if arm is not None and (
            isinstance(arm, bool) or not isinstance(arm, int | float) or not 0 <= arm <= ARMATURE_MAX
        ):
            raise ConfigError("armature", f"must be a number in 0 .. {ARMATURE_MAX:g} kg m^2, got {arm!r}")
        _positive("pi_kp", self.pi_kp, optional=True)
        ki = self.pi_ki
        if ki is not None and (
            isinstance(ki, bool) or not isinstance(ki, int | float) or not math.isfinite(ki) or ki < 0
        ):
            raise ConfigError("pi_ki", f"must be a number >= 0, got {ki!r}")
        self.noise_std()
        self.motion_noise_std()
        check_sensing(self)
        if is_menagerie(self.model):  # resolved (perhaps downloaded) when the robot is read, not here
            menagerie_name(self.model)
        else:
            model_path(self.model)

    @property
    def path(self) -> Path:
        """The model file (a scenario file's relative path was resolved from its folder when it was
        loaded; a Menagerie robot is resolved by mujoco-menagerie)."""
        return model_path(self.model)

    @property
    def frame(self) -> tuple[str, str]:
        """("site" or "body", name) of the pose frame (once found: see mlpfac.plants.mjcf.detect)."""
        return ("body", self.body) if self.body is not None else ("site", self.site or "axle_mid")

    @property
    def offset(self) -> tuple[float, float, float]:
        """The pose frame's offset from the site or body (m), zero when none is set."""
        return (0.0, 0.0, 0.0) if self.frame_offset is None else self.frame_offset

    def noise_std(self) -> np.ndarray | None:
        """(3,) standard deviations of the pose noise, or None when there is none."""
        std = _stds("pose_noise_std", self.pose_noise_std, 3, "")
        _in_range("pose_noise_std", std, " (m, m, rad)", self.pose_noise_std)
        return std.copy() if np.any(std > 0) else None

    def motion_noise_std(self) -> np.ndarray | None:
        """(4,) standard deviations of the noise on (v, omega, wheel_l, wheel_r) as a torque-level
        controller measures them, or None when there is none."""
        twist = _stds("twist_noise_std", self.twist_noise_std, 2, " (m/s, rad/s)")
        w = self.wheel_speed_noise_std
        if isinstance(w, bool) or not isinstance(w, int | float):
            raise ConfigError("wheel_speed_noise_std", f"expected a number (rad/s), got {w!r}")
        std = np.array([*twist, w, w], dtype=float)
        for key, x in (("twist_noise_std", std[:2]), ("wheel_speed_noise_std", std[2:])):
            _in_range(key, x, "", x.tolist())
        return std if np.any(std > 0) else None


def _stds(key: str, value, n: int, units: str) -> np.ndarray:
    """(n,) standard deviations from a number or n numbers; else a ConfigError naming ``key``."""
    try:
        return np.broadcast_to(np.asarray(value, dtype=float), (n,))
    except (TypeError, ValueError):
        raise ConfigError(key, f"expected a number or {n} numbers{units}, got {value!r}") from None


def _in_range(key: str, std: np.ndarray, units: str, given) -> None:
    """Each standard deviation finite, in 0 .. NOISE_STD_MAX; else a ConfigError naming ``key`` and ``given``."""
    if not np.all(np.isfinite(std)) or np.any(std < 0) or np.any(std > NOISE_STD_MAX):
        raise ConfigError(key, f"standard deviations must lie in 0 .. {NOISE_STD_MAX:g}{units}, got {given!r}")
