"""The differential drive's dynamic model with the centre of mass off the axle (Fierro & Lewis 1997;
Dhaouadi & Hatab 2013), written once: M vdot + V(v) v + F(v) = B tau + f_e in the body's velocities
v = (v, omega) of the axle midpoint, the wheels rolling without slip (docs/equations.md)::

    M = diag(m + 2 I_w / r^2,  I + 2 b^2 I_w / r^2)        b = track / 2
    V(v) v = (-m d omega^2,  m d omega v)                 d: centre of mass ahead of the axle
    F(v) = (2 c v / r^2,  2 c b^2 omega / r^2)            c: each wheel's joint damping
    B tau = ((tau_l + tau_r) / r,  b (tau_r - tau_l) / r)
    f_e = (F . h,  tau_z + d F . n)                       an external force F at the centre of mass (h the
                                                          heading, n its left normal; gravity's m g on a slope)

``m`` is the robot's mass (wheels included), ``I`` its yaw inertia about the vertical through the
axle midpoint, ``I_w`` a wheel's inertia about its axle (its rotor's armature included), ``tau``
the wheels' torques (forward positive). On the ground floor beside :mod:`mlpfac.model`: the MuJoCo
plants read a robot's :class:`RobotModel` (:mod:`mlpfac.plants.mjcf.dynamics`), the torque-level
controllers are given it. The compiled, batch-first forms (:func:`accelerations`, :func:`torques`)
are what the controllers step; :meth:`RobotModel.accelerations` and :meth:`RobotModel.torques`
call them.
"""

from __future__ import annotations

import math
from dataclasses import astuple, dataclass, fields

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.jit import kernel

# packed model (RobotModel.packed): the constants the kernels read, by index; P_FV, P_FW the
# external generalized force f_e on (v, omega) (0 in the nominal model; an oracle told a slope or a
# force sets them, mlpfac.control.dynamic)
P_M11, P_M22, P_MD, P_R, P_B, P_C, P_TMAX, P_WMAX = range(8)
P_FV, P_FW = 8, 9
N_P = 10


@dataclass(frozen=True)
class RobotModel:
    """The nominal dynamic parameters of a differential-drive robot, read from its model: the ``robot``
    a torque-level controller is built with (``Class(T=..., robot=..., **params)``)."""

    mass_kg: float  # the whole robot, wheels included
    yaw_inertia_kg_m2: float  # about the vertical through the axle midpoint, other joints locked
    com_offset_m: float  # the centre of mass ahead of the axle midpoint (negative: behind)
    wheel_radius_m: float
    track_m: float  # wheel separation
    wheel_inertia_kg_m2: float  # one wheel about its axle, its rotor's armature included
    torque_limit_Nm: float  # noqa: N815 - the unit in the name; each wheel's largest torque (inf: not limited)
    wheel_damping_Nm_s: float = 0.0  # noqa: N815 - each wheel joint's viscous damping, N m per rad/s
    com_lateral_m: float = 0.0  # the centre of mass left of the axle midpoint (the model takes it as 0)
    wheel_speed_limit_rad_s: float = math.inf  # each wheel's rated speed, the plant's max_wheel_speed (inf: none)

    def __post_init__(self) -> None:
        for f in fields(self):
            x = getattr(self, f.name)
            if isinstance(x, bool) or not isinstance(x, int | float) or math.isnan(x):
                raise ConfigError(f.name, f"expected a number, got {x!r}")
        for name in ("mass_kg", "yaw_inertia_kg_m2", "wheel_radius_m", "track_m", "torque_limit_Nm",
                     "wheel_speed_limit_rad_s"):  # fmt: skip
            if not getattr(self, name) > 0:
                raise ConfigError(name, f"must be positive, got {getattr(self, name)!r}")
        if not self.wheel_inertia_kg_m2 >= 0 or not self.wheel_damping_Nm_s >= 0:
            raise ConfigError("wheel_inertia_kg_m2", "a wheel's inertia and damping are at least 0")

    @property
    def b(self) -> float:
        """Half the track (m)."""
        return 0.5 * self.track_m

    def packed(self) -> np.ndarray:
        """The constants of the kernels (P_M11 .. P_WMAX): M's diagonal, m d, r, b, c, the torque limit,
        the wheel-speed limit."""
        r, b, iw = self.wheel_radius_m, self.b, self.wheel_inertia_kg_m2
        p = np.empty(N_P)
        p[P_M11] = self.mass_kg + 2.0 * iw / (r * r)
        p[P_M22] = self.yaw_inertia_kg_m2 + 2.0 * b * b * iw / (r * r)
        p[P_MD] = self.mass_kg * self.com_offset_m
        p[P_R], p[P_B], p[P_C], p[P_TMAX] = r, b, self.wheel_damping_Nm_s, self.torque_limit_Nm
        p[P_WMAX] = self.wheel_speed_limit_rad_s
        p[P_FV], p[P_FW] = 0.0, 0.0
        return p

    def accelerations(self, twist: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """(vdot, omegadot) of the twist (v, omega) under wheel torques (tau_l, tau_r): (2,) or (B, 2)."""
        tw, ta = _rows(twist), _rows(tau)
        out = np.empty_like(tw)
        accelerations(self.packed(), tw, ta, out)
        return out[0] if np.ndim(twist) == 1 else out

    def torques(self, twist: np.ndarray, accel: np.ndarray) -> np.ndarray:
        """The wheel torques (tau_l, tau_r) that give (vdot, omegadot) at the twist (v, omega), unclamped."""
        tw, ac = _rows(twist), _rows(accel)
        out = np.empty_like(tw)
        torques(self.packed(), tw, ac, out)
        return out[0] if np.ndim(twist) == 1 else out

    def as_dict(self) -> dict[str, float]:
        return dict(zip((f.name for f in fields(self)), astuple(self), strict=True))


def _rows(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float).reshape(-1, 2)


@kernel()
def accel_of(p, v, w, tl, tr):
    """M^-1 (B tau + f_e - V(v) v - F(v)): (vdot, omegadot) of one robot."""
    r, b, c = p[P_R], p[P_B], p[P_C]
    fv = (tl + tr) / r + p[P_MD] * w * w - 2.0 * c * v / (r * r) + p[P_FV]
    fw = b * (tr - tl) / r - p[P_MD] * w * v - 2.0 * c * b * b * w / (r * r) + p[P_FW]
    return fv / p[P_M11], fw / p[P_M22]


@kernel()
def torque_of(p, v, w, a, alpha):
    """B^-1 (M vdot + V(v) v + F(v) - f_e): the wheel torques (tau_l, tau_r) for (vdot, omegadot) = (a, alpha)."""
    r, b, c = p[P_R], p[P_B], p[P_C]
    sv = p[P_M11] * a - p[P_MD] * w * w + 2.0 * c * v / (r * r) - p[P_FV]  # (tau_l + tau_r) / r
    sw = p[P_M22] * alpha + p[P_MD] * w * v + 2.0 * c * b * b * w / (r * r) - p[P_FW]  # b (tau_r - tau_l) / r
    total, diff = sv * r, sw * r / b
    return 0.5 * (total - diff), 0.5 * (total + diff)


@kernel("void(f8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])")
def accelerations(p, twist, tau, out):
    """(vdot, omegadot) (B, 2) for twists (B, 2) and wheel torques (B, 2)."""
    for i in range(twist.shape[0]):
        out[i, 0], out[i, 1] = accel_of(p, twist[i, 0], twist[i, 1], tau[i, 0], tau[i, 1])


@kernel("void(f8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])")
def torques(p, twist, accel, out):
    """Wheel torques (B, 2) for twists (B, 2) and accelerations (B, 2) (the inverse of :func:`accelerations`)."""
    for i in range(twist.shape[0]):
        out[i, 0], out[i, 1] = torque_of(p, twist[i, 0], twist[i, 1], accel[i, 0], accel[i, 1])
