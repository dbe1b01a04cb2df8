"""What a reference may ask of a robot: ``SHARE`` of its wheels' limits (every kind, on every
robot: :mod:`mlpfac.scenario.on_robot`), and a path's limits taken from the robot it is driven by
(:func:`fitted_path`) or, on the kinematic model, from the controller's (:mod:`mlpfac.scenario.waypoints`).
"""

from __future__ import annotations

SHARE = 0.5  # the reference's peak wheel speed, as a share of the robot's wheel-speed limit
ACCEL_TIME = 1.0  # s: without a robot's torque, a path's accelerations reach its speed limits in this time


def fitted_path(ref: dict, r, ctrl, robot: bool) -> tuple[dict, dict, str, str]:
    """A path's ``[reference]`` table ``ref`` timed for robot ``r`` (:mod:`mlpfac.scenario.path`): its
    limits SHARE of the robot's, written in where the table leaves them unset (``robot``: ``--robot``,
    where a limit the table sets is kept only where it is lower, and the track is the robot's).

    - v_max = SHARE r w_max (a wheel's rim speed; w_max: :func:`wheel_speed_limit`, else the
      controller's v_max / r), omega_max = 2 v_max / b: |v| + |omega| b / 2 <= v_max;
    - a_max = SHARE r wdot_max, alpha_max = 2 a_max / b, wdot_max the smaller of what the wheels'
      largest torque gives the robot's inertia (:func:`wheel_accel_limit`) and w_max / ACCEL_TIME
      (where nothing limits the torque: the wheels reach their speed limit in ACCEL_TIME);
    - track = b.

    Returns the table, the controller's limits from the robot (as :func:`mlpfac.scenario.on_robot.fitted`),
    what was done, and a warning ("" where none) where the path, at its ``speed``, asks a wheel's rim
    more speed than the wheels give or more acceleration than their torque gives the robot (as a
    curve that asks more than the wheels give is warned)."""
    from mlpfac.plants.mjcf.wheels import wheel_accel_limit, wheel_speed_limit

    rr, b = float(r.real_radius), float(r.real_track)
    w_max = wheel_speed_limit(r)
    law_v, law_omega = law_limits(ctrl)
    w = w_max if w_max is not None else law_v / rr
    torque = wheel_accel_limit(r)
    wdot = min(w / ACCEL_TIME, torque) if torque is not None else w / ACCEL_TIME
    rim, acc = SHARE * rr * w, SHARE * rr * wdot
    robots = {"v_max": rim, "omega_max": 2 * rim / b, "a_max": acc, "alpha_max": 2 * acc / b, "track": b}
    if w_max is None:  # the controller's limits are the robot's: its omega_max too
        robots["omega_max"] = min(robots["omega_max"], SHARE * law_omega)
    out = dict(ref)
    for key, value in robots.items():
        value = float(f"{value:.6g}")
        if key not in out or (robot and (key == "track" or not out[key] <= value)):
            out[key] = value
    kept = [k for k in ("v_max", "a_max") if out[k] != float(f"{robots[k]:.6g}")]  # the file's own
    limits = f"v_max {out['v_max']:g} m/s at the rim, a_max {out['a_max']:g} m/s^2, track {out['track']:g} m"
    said = (
        f"path timed within {SHARE:g} of the wheels' limits ({limits})"
        if not kept
        else f"path timed within {limits} ({' and '.join(kept)} as the file sets, the rest {SHARE:g} of the wheels')"
    )
    limits = {}
    if w_max is not None:
        limits = {"v_max": float(f"{rr * w_max:.6g}"), "omega_max": float(f"{2 * rr * w_max / b:.6g}")}
    k = float(out.get("speed", 1.0))
    warn = []
    if w_max is not None and k * out["v_max"] > rr * w_max:
        give = rr * w_max
        warn.append(
            f"the path asks a wheel's rim {k * out['v_max']:.3g} m/s (v_max {out['v_max']:g}"
            + (f" x speed {k:g}" if k != 1.0 else "")
            + f") of wheels that give {give:.3g} m/s (x{k * out['v_max'] / give:.3g}): beyond it the IK slows both "
            f"wheels (the path's curvature kept) and the robot falls behind; v_max = {SHARE * give / k:.3g} drives "
            f"it at {SHARE:g} of the limit"
        )
    if torque is not None and k * k * out["a_max"] > rr * torque:
        give = rr * torque
        warn.append(
            f"the path asks {k * k * out['a_max']:.3g} m/s^2 of a wheel's rim (a_max {out['a_max']:g}"
            + (f" x speed {k:g}^2" if k != 1.0 else "")
            + f") where the wheels' torque gives the robot {give:.3g} m/s^2: a_max = {SHARE * give / (k * k):.3g} "
            f"keeps it at {SHARE:g} of that"
        )
    return out, limits, said, "; ".join(warn)


def law_limits(ctrl) -> tuple[float, float]:
    """The controller table's (v_max, omega_max), the law's defaults where it leaves them unset or unlimited."""
    import dataclasses

    from mlpfac.control.law import Law

    out = []
    for f in dataclasses.fields(Law):
        if f.name in ("v_max", "omega_max"):
            x = ctrl.get(f.name) if isinstance(ctrl, dict) else None
            out.append(float(x) if isinstance(x, int | float) and 0 < x < float("inf") else f.default)
    return out[0], out[1]
