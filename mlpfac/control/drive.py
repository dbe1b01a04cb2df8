"""What a wheel drive gives a law of the torque level (:mod:`mlpfac.control.torque`): the wheels' rated
speed kept and a traction guard, written once. The shipped torque-level laws (``fierro-lewis``,
``oracle-dynamic``, ``adaptive-dynamic``) step these kernels; a law of one's own calls them through
:class:`mlpfac.control.torque.Drive`. The plant applies the torques it is sent, as the contract
says: nothing here is physics.

- **Rated speed.** A velocity command (v_c, omega_c) whose faster wheel, (v_c -+ omega_c b) / r,
  would pass the rated speed w_max is scaled, both together, to bring it there (:func:`rated`: the
  IK's rule, :func:`mlpfac.plants.ik.wheel_speeds`, the curvature kept), and its rate with it. The
  torque that drives a wheel past w_max falls linearly to zero over the next ``RATED_BAND`` of it
  (a band below w_max would keep the wheels from the speed the command asks: on TIAGo at twice
  the eight's speed, where the reference asks the rated 5 rad/s, 10 % below it cost 2-4x).
- **Traction.** A wheel turning at w (its encoder) over ground that moves at g = (v -+ omega b) / r
  (the base's measured twist) slips by w - g. Slip up to ``SLIP_SPEED`` / r + ``SLIP_RATIO``
  min(|w|, |g|) is rolling (:func:`rolling`); beyond it the torque that spins the wheel on, faster
  than the ground in its own direction, falls linearly to zero at twice that, and comes back as
  the wheel grips again. ``SLIP_RATIO`` = 0.6 lets a wheel turn 1.6 times as fast as the ground
  before it is taken to spin (a rolling radius down to 1/1.6 of the nominal one is a gain the laws
  meet, not a lost grip); ``SLIP_SPEED`` is what the measurements' noise and a tyre's creep give
  near rest. The threshold grows with the slower of the two speeds, so that a spinning wheel does
  not raise its own. A wheel slower than the ground (braked to a skid) keeps its torque: a locked
  wheel throws no robot, and cutting its braking (an ABS) cost more where the robot itself skids
  (the tug after its radius grows) than it gained on a wet floor (docs/controllers.md).

Where neither part acts the torques are the law's to the bit. With no wheel-speed limit
(w_max = inf) the first part does nothing. A limit on the torque's rate is not here: it made the
runs worse wherever it acted (docs/controllers.md).
"""

from __future__ import annotations

from mlpfac.dynamics import P_B, P_R, P_TMAX, P_WMAX
from mlpfac.jit import kernel

RATED_BAND = 0.02  # the torque that drives a wheel past w_max falls to zero over this share of w_max past it
SLIP_RATIO = 0.6  # slip, as a share of the slower of the wheel and the ground, that is rolling
SLIP_SPEED = 0.05  # m/s at the contact: slip that is rolling at any speed (noise, a tyre's creep)


@kernel()
def rated(p, v, w, dv, dw):
    """(v, omega) and its rate (dv, domega) as the drive takes them: both scaled by s = w_max / the
    faster wheel's speed where that passes w_max (the curvature kept), the rate the scaled
    command's own, s ((dv, domega) - (v, omega) dpeak / peak); as given otherwise."""
    r, b, wmax = p[P_R], p[P_B], p[P_WMAX]
    wl, wr = (v - w * b) / r, (v + w * b) / r
    if abs(wl) >= abs(wr):
        peak, dpeak = abs(wl), (dv - dw * b) / r
        if wl < 0.0:
            dpeak = -dpeak
    else:
        peak, dpeak = abs(wr), (dv + dw * b) / r
        if wr < 0.0:
            dpeak = -dpeak
    if not peak > wmax:
        return v, w, dv, dw
    s, q = wmax / peak, dpeak / peak
    return s * v, s * w, s * (dv - v * q), s * (dw - w * q)


@kernel()
def rolling(p, w, g):
    """The largest slip |w - g| (rad/s) with which a wheel turning at ``w`` over ground moving at ``g`` rolls."""
    return SLIP_SPEED / p[P_R] + SLIP_RATIO * min(abs(w), abs(g))


@kernel()
def _kept(p, tau, w, g):
    """The share of the torque ``tau`` the drive sends to a wheel turning at ``w`` over ground moving
    at ``g`` (rad/s): 1 but past the rated speed in the torque's direction, or where the torque
    spins the wheel, in its own direction, faster than the ground beyond rolling."""
    if tau == 0.0:
        return 1.0
    d = 1.0 if tau > 0.0 else -1.0
    kept = 1.0
    over = d * w - p[P_WMAX]  # how far past w_max the torque pushes the wheel
    if over > 0.0:
        kept = max(1.0 - over / (RATED_BAND * p[P_WMAX]), 0.0)
    slip, rolls = d * (w - g), rolling(p, w, g)  # the slip the torque drives on, and what rolls
    if slip > rolls and d * w > 0.0:  # spinning on (a wheel braked to a skid keeps its torque)
        kept = min(kept, max(2.0 - slip / rolls, 0.0))
    return kept


@kernel()
def guard(p, v, w, wl, wr, tl, tr):
    """The wheel torques the drive sends for the law's (tl, tr), each cut past the rated speed and
    where it spins its wheel beyond rolling (:func:`_kept`), within the torque limit: (v, w) the
    base's measured twist, (wl, wr) the encoders' wheel speeds."""
    r, b, tmax = p[P_R], p[P_B], p[P_TMAX]
    gl, gr = (v - w * b) / r, (v + w * b) / r  # the ground's speed under each wheel, in wheel speed
    tl = tl * _kept(p, tl, wl, gl)
    tr = tr * _kept(p, tr, wr, gr)
    return min(max(tl, -tmax), tmax), min(max(tr, -tmax), tmax)


@kernel()
def slipping(p, v, w, wl, wr):
    """Whether a wheel slips beyond rolling (:func:`rolling`), spinning or skidding: (v, w) the base's
    measured twist, (wl, wr) the encoders' wheel speeds."""
    r, b = p[P_R], p[P_B]
    gl, gr = (v - w * b) / r, (v + w * b) / r
    return abs(wl - gl) > rolling(p, wl, gl) or abs(wr - gr) > rolling(p, wr, gr)


@kernel("void(f8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])")
def drive_step(p, twist, wheels, tau):
    """For B seeds, in place: the torques ``tau`` (B, 2) the law asked become those the drive sends
    (:func:`guard`), given the measured ``twist`` (B, 2) and the encoders' ``wheels`` (B, 2) rad/s."""
    for i in range(tau.shape[0]):
        tau[i, 0], tau[i, 1] = guard(p, twist[i, 0], twist[i, 1], wheels[i, 0], wheels[i, 1], tau[i, 0], tau[i, 1])


@kernel("void(f8[::1], f8[:, ::1], f8[:, ::1])")
def rated_step(p, cmd, rate):
    """For B seeds, in place: the velocity commands ``cmd`` (B, 2) = (v_c, omega_c) and their rates
    ``rate`` (B, 2) kept within the rated wheel speed (:func:`rated`)."""
    for i in range(cmd.shape[0]):
        cmd[i, 0], cmd[i, 1], rate[i, 0], rate[i, 1] = rated(p, cmd[i, 0], cmd[i, 1], rate[i, 0], rate[i, 1])
