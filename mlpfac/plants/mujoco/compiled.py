"""The MuJoCo plant's control step, compiled: wheel commands in, physics, pose, noise, telemetry and
the divergence test out, with MuJoCo's own C functions called from the kernel (no Python per step).

:class:`~mlpfac.plants.mujoco.plant.MujocoPlant` steps through :func:`plant_step` one control step at a
time, and the compiled closed loop (:mod:`mlpfac.loop.compiled`) runs it for many steps in one call: one
implementation of the step either way. The C functions are the ones the ``mujoco`` package's
bindings call (``mj_step``, ``mj_step1``, ``mj_step2``, ``mj_objectVelocity``, ``mj_getState``),
from the library the package ships, so a compiled step gives the bindings' bits; the kernels name
them, so the module built at install (``mlpfac.plants._kernels``, :mod:`mlpfac.jit`) finds them in
the library loaded here, and numba, where it compiles the kernels, as ``ExternalFunction``.

MuJoCo reports a fatal engine error (an arena too small for the model, say) through
``mju_user_error``. Inside the bindings it becomes ``mujoco.FatalError``; a C call from a kernel
cannot raise, so the handler installed here prints one line naming the error and ends the process
with exit status 1 (MuJoCo's own handler would wait for Enter on a terminal).

Layout of the per-robot arrays (indices below): ``ints`` (int64) and ``fl`` (float64) hold what the
robot is, ``st`` (float64) what changes every step.
"""

from __future__ import annotations

import ctypes
import glob
import math
import os
import sys
from typing import NamedTuple

import mujoco
import numpy as np

from mlpfac.elementary import atan2, cos, sin
from mlpfac.exceptions import ConfigError
from mlpfac.jit import SALT, WHY, built, kernel
from mlpfac.plants.events import delay_push
from mlpfac.plants.ik import body_velocity_vw, wheel_speeds_lr
from mlpfac.plants.sensors.odometry import O_GADR, O_GYRO, O_QL, O_QR, O_X, sense_step
from mlpfac.plants.world.terrain import W_NPATCH, W_NTILE, ground_at, patches, place_tiles, push

# ints: I_AL2, I_AR2 a second wheel's actuator on each side (skid-steer; -1: none), I_MIX 1 for two
# motors on tendons over both wheels (a (v, omega) drive; I_AL, I_AR are those motors), I_CLAMP 1 for
# servos whose force limit the plant keeps through their control (servo_limit = "control"), I_DL2,
# I_DR2 the second wheels' dof addresses, I_TAU 1 when the command is the wheels' torques (a
# torque-level controller: the torque drive without its PI loop)
I_AL, I_AR, I_DL, I_DR, I_SITE, I_NSUB, I_TORQUE, I_NOISE, I_AL2, I_AR2, I_MIX, I_CLAMP, I_DL2, I_DR2 = range(14)
I_TAU = 14
I_ROOT = 15  # the robot's root body (where a force event pushes)
N_INTS = 16
# fl
F_CL, F_CR, F_SL, F_SR, F_IK_R, F_IK_TRACK, F_WMAX, F_DT, F_KP, F_KI, F_TLMAX, F_TRMAX, F_RADIUS, F_ZREST = range(14)
F_STD = 14  # three pose-noise standard deviations
F_CL2, F_CR2 = 17, 18  # the second wheels' actuator units per forward wheel unit
F_MIX = 19  # (2, 2) row-major: the tendon motors' controls per forward wheel torque (left, right)
F_UMAX = 23  # the tendon motors' control limits (inf: none)
F_BAND = 25  # servo_limit = "control": each servo's (left, right, left 2, right 2) force limit / kv (control units)
F_GEAR = 29  # ... and its gear (actuator velocity per joint velocity)
N_FL = 33
# st: the unwrapped heading, simulated time, the PI integrals, the true pose (x, y, theta), and 1
# once MuJoCo warned during a step of this robot (set by the warning handler below)
S_THETA, S_TIME, S_IL, S_IR = range(4)
S_POSE = 4
S_WARN = 7
N_ST = 8
# one row of telemetry: u_meas, u_true, wheel_cmd, wheel_meas, torque (two each)
TELEMETRY = ("u_meas", "u_true", "wheel_cmd", "wheel_meas", "torque")
N_TELE = 2 * len(TELEMETRY)
# why a step diverged (0: it did not)
RESET, NOT_FINITE, LIFTED, TIPPED, WARNED = 1, 2, 3, 4, 5
STATE_TIME = int(mujoco.mjtState.mjSTATE_TIME)
OBJ_SITE = int(mujoco.mjtObj.mjOBJ_SITE)


class Robot(NamedTuple):
    """What the compiled step reads and writes of one robot: the addresses of the current MjModel and
    MjData, views into the data, the robot's arrays, the delay line and a work array (valid until
    an event replaces the model or the delay line)."""

    mp: int
    dp: int
    ctrl: np.ndarray
    qvel: np.ndarray
    qpos: np.ndarray
    qfrc: np.ndarray  # qfrc_actuator
    site_xpos: np.ndarray
    site_xmat: np.ndarray
    root_xmat: np.ndarray
    ints: np.ndarray
    fl: np.ndarray
    st: np.ndarray
    hist: np.ndarray
    fill: np.ndarray
    vel: np.ndarray  # (6,) mj_objectVelocity's output
    sense: np.ndarray  # the pose source's estimator (mlpfac.plants.sensors.odometry's layout); empty: the truth
    sensordata: np.ndarray  # MjData.sensordata (the gyro's reading)
    # the world (mlpfac.plants.mujoco.world, mlpfac.plants.world.terrain): the data's xfrc_applied, geom_xpos,
    # mocap_pos, mocap_quat and the model's geom_friction (flat), the packed world ((0,): none), the
    # rough ground's nodes, the force schedule (steps, 5)
    xfrc: np.ndarray
    geom_xpos: np.ndarray
    mocap_pos: np.ndarray
    mocap_quat: np.ndarray
    geom_friction: np.ndarray
    world: np.ndarray
    nodes: np.ndarray
    push: np.ndarray


def _library() -> str:
    here = os.path.dirname(mujoco.__file__)
    names = [
        n for pat in ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll") for n in glob.glob(os.path.join(here, pat))
    ]
    if not names:
        raise ImportError(f"mlpfac: the MuJoCo library was not found beside the mujoco package in {here}")
    return sorted(names)[-1]


_LIB_PATH = _library()
# The kernels call MuJoCo's functions by name: the built module (mlpfac.plants._kernels) finds them in
# the library loaded here, numba (when it compiles them) through llvmlite.
_LIB = ctypes.CDLL(_LIB_PATH, mode=ctypes.RTLD_GLOBAL)
SALT["mujoco"] = mujoco.__version__  # its enums and functions, as the module was built against them
if built("mujoco") is None and built("core") is not None:  # numba cannot call the built core kernels
    raise ConfigError(WHY["mujoco"], "reinstall mlpfac (pip install --force-reinstall --no-deps mlpfac)")
if built("mujoco") is None:
    import llvmlite.binding as llvm
    from numba import types

    llvm.load_library_permanently(_LIB_PATH)
    _P = types.intp  # pointers are passed as addresses (MjModel._address, ndarray.ctypes.data)
    mj_step = types.ExternalFunction("mj_step", types.void(_P, _P))
    mj_step1 = types.ExternalFunction("mj_step1", types.void(_P, _P))
    mj_step2 = types.ExternalFunction("mj_step2", types.void(_P, _P))
    mj_objectVelocity = types.ExternalFunction(  # noqa: N816 - MuJoCo's name
        "mj_objectVelocity", types.void(_P, _P, types.int32, types.int32, _P, types.int32)
    )
    mj_getState = types.ExternalFunction(  # noqa: N816 - MuJoCo's name
        "mj_getState", types.void(_P, _P, _P, types.uint32)
    )
    _remainder = types.ExternalFunction("remainder", types.float64(types.float64, types.float64))  # IEEE, exact
    from numba import carray
    from numba.extending import intrinsic

    @intrinsic
    def address(typingctx, addr):
        """A whole number as the pointer it is (an array's address, from :func:`robot_row`)."""

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(types.voidptr))

        return types.voidptr(types.int64), codegen


ROW = 2 + 3 * (len(Robot._fields) - 2)  # a robot as a row of numbers: mp, dp, then (address, rows, columns) an array


def robot_row(robot: Robot, row: np.ndarray) -> None:
    """``robot``'s arrays by address into ``row`` (ROW,) int64, as :func:`robot_at` reads them back
    in a kernel that steps many robots (:func:`mlpfac.loop.compiled.across`). The arrays must outlive
    every call that reads the row: the caller keeps ``robot``."""
    row[0], row[1] = robot.mp, robot.dp
    for i, a in enumerate(robot[2:]):
        assert a.flags.c_contiguous and a.dtype in (np.float64, np.int64)
        row[2 + 3 * i : 5 + 3 * i] = a.ctypes.data, a.shape[0], a.shape[1] if a.ndim == 2 else 1


@kernel()
def f1_at(t, j):
    """The float64 vector whose (address, length) a row holds at j."""
    return carray(address(t[j]), t[j + 1], np.float64)


@kernel()
def i1_at(t, j):
    return carray(address(t[j]), t[j + 1], np.int64)


@kernel()
def f2_at(t, j):
    """The float64 matrix whose (address, rows, columns) a row holds at j."""
    return carray(address(t[j]), (t[j + 1], t[j + 2]), np.float64)


@kernel()
def robot_at(t):
    """The :class:`Robot` whose arrays a row of :func:`robot_row` holds (views of the same memory)."""
    return Robot(t[0], t[1], f1_at(t, 2), f1_at(t, 5), f1_at(t, 8), f1_at(t, 11), f1_at(t, 14), f1_at(t, 17), f1_at(t, 20),
                 i1_at(t, 23), f1_at(t, 26), f1_at(t, 29), f2_at(t, 32), i1_at(t, 35), f1_at(t, 38), f1_at(t, 41), f1_at(t, 44),
                 f1_at(t, 47), f1_at(t, 50), f1_at(t, 53), f1_at(t, 56), f1_at(t, 59), f1_at(t, 62), f2_at(t, 65), f2_at(t, 68))  # fmt: skip


def with_robot(signature: str, *more):
    """numba's ``signature`` with the types ``more`` and a last argument of :class:`Robot`, for
    :func:`~mlpfac.jit.kernel`."""
    from numba import types
    from numba.core.sigutils import normalize_signature

    args, ret = normalize_signature(signature)
    f1, i1 = types.float64[::1], types.int64[::1]
    f2 = types.float64[:, ::1]
    fields = (types.int64, types.int64, *[f1] * 7, i1, f1, f1, f2, i1, f1, f1, f1, *[f1] * 6, f2, f2)
    assert len(fields) == len(Robot._fields), "with_robot names a type for each field of Robot, in order"
    return ret(*args, *more, types.NamedTuple(fields, Robot))


@ctypes.CFUNCTYPE(None, ctypes.c_char_p)
def _fatal(msg: bytes) -> None:
    text = " ".join(msg.decode(errors="replace").split())  # one line
    sys.stderr.write(f"error: MuJoCo: {text} (a fatal engine error in a compiled step)\n")
    sys.stderr.flush()
    os._exit(1)


ctypes.c_void_p.in_dll(_LIB, "mju_user_error").value = ctypes.cast(_fatal, ctypes.c_void_p).value

WARNINGS: list[str] = []  # MuJoCo's warnings in this process, newest last (at most a few kept)
_WATCHED: list = [None]  # the st array of the robot stepping now (watch), or of many (watch_many)
STEPPING = np.zeros(1, dtype=np.int64)  # which of many watched robots steps now (a kernel sets it)


def watch(st: np.ndarray | None) -> None:
    """Name the robot (its ``st``) that steps next: a warning of MuJoCo marks it (``st[S_WARN]``),
    and its next divergence test ends its run (WARNED)."""
    _WATCHED[0] = st


def watch_many(sts: list[np.ndarray]) -> None:
    """Name the robots a kernel steps in turn, writing which one steps now into :data:`STEPPING`."""
    _WATCHED[0] = sts


@ctypes.CFUNCTYPE(None, ctypes.c_char_p)
def _warning(msg: bytes) -> None:
    """MuJoCo's warnings (an unstable simulation it resets, a control it zeroes, a full arena):
    kept here, neither printed nor written to MUJOCO_LOG.TXT in the current folder."""
    WARNINGS.append(" ".join(msg.decode(errors="replace").split()))
    del WARNINGS[:-4]
    st = _WATCHED[0]
    if isinstance(st, list):
        st = st[int(STEPPING[0])]
    if st is not None:
        st[S_WARN] = 1.0


ctypes.c_void_p.in_dll(_LIB, "mju_user_warning").value = ctypes.cast(_warning, ctypes.c_void_p).value


@kernel("f8(f8[::1])", ext="mujoco", error_model="python")
def yaw(xmat: np.ndarray) -> float:
    """Heading of a frame: the angle of its x axis projected on the floor, atan2(R[1, 0], R[0, 0])."""
    return atan2(xmat[3], xmat[0])


@kernel()
def _physics(mp, dp, ctrl, qvel, ints, fl, st, wl, wr, robot):
    """One control period: the wheel commands held for n physics steps, each ``mj_step2`` (actuation,
    integration) then ``mj_step1`` (the new state's positions, velocities, sensors). The velocity
    servos are MuJoCo's (with ``I_CLAMP`` their controls kept within their force limits, :func:`_within`,
    every physics step); the torque drive is a discrete wheel-speed PI loop evaluated every physics
    step: tau = kp e + ki I, clamped to the torque limit, I integrating e only while tau is not
    clamped (no wind-up). With ``I_TAU`` (wl, wr) are the wheels' torques themselves, clamped to
    the limit and held. On rough ground the contact tiles are placed before each physics step's
    collisions (:func:`mlpfac.plants.world.terrain.place_tiles`)."""
    n, al, ar, dl, dr = ints[I_NSUB], ints[I_AL], ints[I_AR], ints[I_DL], ints[I_DR]
    w = robot.world
    tiles = w.shape[0] > 0 and w[W_NTILE] > 0
    cl, cr = fl[F_CL], fl[F_CR]
    al2, ar2 = ints[I_AL2], ints[I_AR2]
    if ints[I_TORQUE] == 0 and ints[I_CLAMP]:
        dl2, dr2 = ints[I_DL2], ints[I_DR2]
        for _ in range(n):
            ctrl[al] = _within(cl * wl, qvel[dl], fl, 0)
            ctrl[ar] = _within(cr * wr, qvel[dr], fl, 1)
            if al2 >= 0:
                ctrl[al2] = _within(fl[F_CL2] * wl, qvel[dl2], fl, 2)
            if ar2 >= 0:
                ctrl[ar2] = _within(fl[F_CR2] * wr, qvel[dr2], fl, 3)
            mj_step2(mp, dp)
            if tiles:
                place_tiles(w, robot.nodes, robot.geom_xpos, robot.mocap_pos, robot.mocap_quat)
            mj_step1(mp, dp)
    elif ints[I_TORQUE] == 0:
        ctrl[al] = cl * wl
        ctrl[ar] = cr * wr
        if al2 >= 0:
            ctrl[al2] = fl[F_CL2] * wl
        if ar2 >= 0:
            ctrl[ar2] = fl[F_CR2] * wr
        mj_step2(mp, dp)
        for _ in range(n - 1):
            if tiles:
                place_tiles(w, robot.nodes, robot.geom_xpos, robot.mocap_pos, robot.mocap_quat)
            mj_step(mp, dp)
        if tiles:
            place_tiles(w, robot.nodes, robot.geom_xpos, robot.mocap_pos, robot.mocap_quat)
        mj_step1(mp, dp)
    else:
        sl, sr, kp, ki, dt = fl[F_SL], fl[F_SR], fl[F_KP], fl[F_KI], fl[F_DT]
        tl_max, tr_max = fl[F_TLMAX], fl[F_TRMAX]
        il, ir = st[S_IL], st[S_IR]
        direct = ints[I_TAU] != 0
        for _ in range(n):
            el = wl - sl * qvel[dl]
            er = wr - sr * qvel[dr]
            tl = kp * el + ki * (il + el * dt)
            tr = kp * er + ki * (ir + er * dt)
            if direct:
                tl, tr, el, er = wl, wr, 0.0, 0.0
            if ints[I_MIX]:
                il, ir = _mix(ctrl, al, ar, fl, tl, tr, il, ir, el * dt, er * dt)
                mj_step2(mp, dp)
                if tiles:
                    place_tiles(w, robot.nodes, robot.geom_xpos, robot.mocap_pos, robot.mocap_quat)
                mj_step1(mp, dp)
                continue
            if -tl_max <= tl <= tl_max:
                il += el * dt
            else:
                tl = math.copysign(tl_max, tl)
            if -tr_max <= tr <= tr_max:
                ir += er * dt
            else:
                tr = math.copysign(tr_max, tr)
            ctrl[al] = tl / cl
            ctrl[ar] = tr / cr
            if al2 >= 0:
                ctrl[al2] = tl / fl[F_CL2]
            if ar2 >= 0:
                ctrl[ar2] = tr / fl[F_CR2]
            mj_step2(mp, dp)
            if tiles:
                place_tiles(w, robot.nodes, robot.geom_xpos, robot.mocap_pos, robot.mocap_quat)
            mj_step1(mp, dp)
        st[S_IL], st[S_IR] = il, ir
    st[S_TIME] += n * fl[F_DT]


@kernel()
def _within(c, w, fl, i):
    """Servo i's control ``c`` kept within its force limit from the joint speed ``w``: kv |c - gear w|
    at most the limit (force = kv (ctrl - gear w)); MuJoCo then integrates the servo implicitly, which
    it does not while it clamps the force itself (a clamped stiff servo on a light wheel chatters)."""
    v, band = fl[F_GEAR + i] * w, fl[F_BAND + i]
    return min(max(c, v - band), v + band)


@kernel()
def _mix(ctrl, a, b, fl, tl, tr, il, ir, dil, dir_):
    """The tendon drive's two motors' controls for the wheel torques (tl, tr): the inverse of the
    motors' torques on the wheels; both scaled down together (the torques' ratio kept) when one
    passes its control limit, and then the PI integrals held (no wind-up). Returns the integrals."""
    ca = fl[F_MIX] * tl + fl[F_MIX + 1] * tr
    cb = fl[F_MIX + 2] * tl + fl[F_MIX + 3] * tr
    k = max(abs(ca) / fl[F_UMAX], abs(cb) / fl[F_UMAX + 1])
    if k > 1.0:
        ca, cb = ca / k, cb / k
    else:
        il, ir = il + dil, ir + dir_
    ctrl[a], ctrl[b] = ca, cb
    return il, ir


@kernel("void(f8[::1], f8[::1], f8[::1])", ext="mujoco")
def read_pose(site_xpos, site_xmat, st):
    """The pose (x, y, theta) at the site into st, theta the heading atan2(R10, R00) unwrapped across steps."""
    th = st[S_THETA]
    th += _remainder(yaw(site_xmat) - th, 2.0 * math.pi)
    st[S_THETA] = th
    st[S_POSE], st[S_POSE + 1], st[S_POSE + 2] = site_xpos[0], site_xpos[1], th


@kernel("void(i8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], i8[::1])", ext="mujoco")
def measure(ints, fl, st, draw, hist, fill):
    """The true pose plus noise (std * one standard normal draw per coordinate), into the delay line."""
    m = np.empty(3)
    for j in range(3):
        m[j] = st[S_POSE + j]
        if ints[I_NOISE]:
            m[j] = m[j] + fl[F_STD + j] * draw[j]
    delay_push(hist, fill, m)


@kernel()
def sense(draw, tele, robot):
    """The pose the robot estimates (:func:`mlpfac.plants.sensors.odometry.sense_step`: its encoders, the
    driven wheels' hinge angles forward; its gyro; the fixes of its true pose) into the delay line,
    its telemetry after the plant's and the force's (``tele[N_TELE + 3:]`` where a force is applied)."""
    s, fl, st = robot.sense, robot.fl, robot.st
    o = N_TELE + 3 if robot.push.shape[0] else N_TELE
    phl, phr = fl[F_SL] * robot.qpos[int(s[O_QL])], fl[F_SR] * robot.qpos[int(s[O_QR])]
    rate = robot.sensordata[int(s[O_GADR])] if s[O_GYRO] else 0.0
    sense_step(s, phl, phr, rate, st[S_TIME], st[S_POSE], st[S_POSE + 1], st[S_POSE + 2], draw, tele, o)
    m = np.empty(3)
    for j in range(3):
        m[j] = s[O_X + j]
    delay_push(robot.hist, robot.fill, m)


@kernel(lambda: with_robot("i8()"), ext="mujoco")
def diverged(robot):
    """WARNED when MuJoCo warned during a step of this robot, RESET when MuJoCo reset the data on a bad state (its time no longer ours), NOT_FINITE, LIFTED
    when the axle rose half a wheel radius above its rest height, TIPPED when the chassis' up axis is
    more than 60 deg from vertical; 0 when none."""
    fl, st = robot.fl, robot.st
    if st[S_WARN] != 0.0:
        return WARNED
    t = np.empty(1)
    mj_getState(robot.mp, robot.dp, t.ctypes.data, STATE_TIME)
    if abs(t[0] - st[S_TIME]) > 0.5 * fl[F_DT]:
        return RESET
    s = 0.0
    for x in robot.qpos:
        s += x
    for x in robot.qvel:
        s += x
    if not math.isfinite(s):
        return NOT_FINITE
    z = robot.site_xpos[2]
    if robot.world.shape[0]:  # above the ground under it (mlpfac.plants.world.terrain)
        z -= ground_at(robot.world, robot.nodes, robot.site_xpos[0], robot.site_xpos[1])
    if z - fl[F_ZREST] > 0.5 * fl[F_RADIUS]:
        return LIFTED
    if robot.root_xmat[8] < 0.5:
        return TIPPED
    return 0


@kernel(lambda: with_robot("i8(f8, f8, f8[::1], f8[::1])"), ext="mujoco")
def plant_step(u0, u1, draw, tele, robot):
    """One control step of the robot for the command u = (v, omega) (with ``I_TAU``: the wheels'
    torques (tau_l, tau_r) in N m, forward positive, and ``wheel_cmd`` NaN): the IK (wheel speeds the nominal
    radius and track give, scaled together under the wheel-speed limit), the physics, the pose and
    its measurement (noise ``draw`` (3,) of standard normals), the telemetry row ``tele`` (see
    TELEMETRY). Returns why it diverged (0: it did not)."""
    ints, fl, st, qvel, vel = robot.ints, robot.fl, robot.st, robot.qvel, robot.vel
    if ints[I_TAU]:  # the wheels' torques (tau_l, tau_r): no IK, no wheel-speed command
        wl, wr = u0, u1
    else:
        wl, wr = wheel_speeds_lr(u0, u1, fl[F_IK_R], fl[F_IK_TRACK], fl[F_WMAX])
    w = robot.world
    if w.shape[0]:  # the floor patches under the tyres, the force of this step (mlpfac.plants.world.terrain)
        if w[W_NPATCH] > 0:
            patches(w, robot.geom_friction, robot.geom_xpos)
        if robot.push.shape[0]:
            push(w, robot.push, robot.xfrc, ints[I_ROOT], st[S_THETA], tele[N_TELE : N_TELE + 3])
    _physics(robot.mp, robot.dp, robot.ctrl, qvel, ints, fl, st, wl, wr, robot)
    read_pose(robot.site_xpos, robot.site_xmat, st)
    if robot.sense.shape[0]:  # a pose source other than the truth (mlpfac.plants.sensors.sensing)
        sense(draw, tele, robot)
    else:
        measure(ints, fl, st, draw, robot.hist, robot.fill)
    dl, dr, sl, sr = ints[I_DL], ints[I_DR], fl[F_SL], fl[F_SR]
    ml, mr = sl * qvel[dl], sr * qvel[dr]
    mj_objectVelocity(robot.mp, robot.dp, OBJ_SITE, ints[I_SITE], vel.ctypes.data, 0)  # (angular, linear), world
    th = st[S_THETA]
    tele[0], tele[1] = body_velocity_vw(ml, mr, fl[F_IK_R], fl[F_IK_TRACK])
    tele[2], tele[3] = vel[3] * cos(th) + vel[4] * sin(th), vel[2]
    tele[4], tele[5] = (math.nan, math.nan) if ints[I_TAU] else (wl, wr)
    tele[6], tele[7] = ml, mr
    tele[8], tele[9] = sl * robot.qfrc[dl], sr * robot.qfrc[dr]  # as applied: joint limits included
    return diverged(robot)
