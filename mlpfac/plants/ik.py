"""The inverse-kinematics layer (IK) of a differential-drive robot: body velocity (v, omega) <-> wheel speeds.

Wheels of radius ``radius`` (m) on one axle, ``track`` (m) apart; wheel speeds in rad/s, positive
when the wheel drives the robot forward; v in m/s along the heading, omega in rad/s (counter-
clockwise). Rolling without slip at both contact points gives

    v     = radius (w_l + w_r) / 2
    omega = radius (w_r - w_l) / track

and its inverse

    w_l = (v - omega track / 2) / radius
    w_r = (v + omega track / 2) / radius
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.jit import kernel


def wheel_speeds(
    v: float, omega: float, radius: float, track: float, max_wheel_speed: float | None = None
) -> np.ndarray:
    """Inverse kinematics: (2,) wheel speeds [w_l, w_r] in rad/s for the body velocity (v, omega).

    With ``max_wheel_speed`` given, when the faster wheel would exceed it both wheels are scaled
    by the same factor s = max_wheel_speed / max(|w_l|, |w_r|) < 1, so the path curvature
    omega / v (the ratio w_r / w_l) is kept and only the speed along the path drops.
    """
    limit = math.inf if max_wheel_speed is None else float(max_wheel_speed)
    return np.array(wheel_speeds_lr(float(v), float(omega), float(radius), float(track), limit))


@kernel("UniTuple(f8, 2)(f8, f8, f8, f8, f8)", error_model="python")
def wheel_speeds_lr(v: float, omega: float, radius: float, track: float, max_wheel_speed: float) -> tuple[float, float]:
    """:func:`wheel_speeds` as two floats, compiled (the plant's control step calls it); no limit: inf."""
    half = 0.5 * omega * track
    w_l = (v - half) / radius
    w_r = (v + half) / radius
    peak = max(abs(w_l), abs(w_r))
    if peak > max_wheel_speed:
        s = max_wheel_speed / peak
        w_l, w_r = s * w_l, s * w_r
    return w_l, w_r


def body_velocity(wheel_lr: np.ndarray, radius: float, track: float) -> np.ndarray:
    """Forward kinematics: (2,) body velocity [v, omega] from wheel speeds [w_l, w_r] in rad/s.

    v = radius (w_l + w_r) / 2, omega = radius (w_r - w_l) / track.
    """
    return np.array(body_velocity_vw(float(wheel_lr[0]), float(wheel_lr[1]), float(radius), float(track)))


@kernel("UniTuple(f8, 2)(f8, f8, f8, f8)", error_model="python")
def body_velocity_vw(w_l: float, w_r: float, radius: float, track: float) -> tuple[float, float]:
    """:func:`body_velocity` as two floats, compiled."""
    return 0.5 * radius * (w_l + w_r), radius * (w_r - w_l) / track
