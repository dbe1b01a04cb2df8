"""The closed loop compiled between events: many control steps of one seed in one kernel call.

For a plant with a compiled control step (the MuJoCo robot, :mod:`mlpfac.plants.mujoco.compiled`) and a
controller whose step is a kernel (Kanayama, Corradini: :func:`mlpfac.control.law.law_step`; the
oracles told the changes without a sensor delay: :func:`mlpfac.control.oracle.told_step`; the
adaptive scheme's compiled form: :func:`adaptive_row`), the
runner steps each seed from one event (or sink flush) to the next with :func:`segment`. Every
step is the runner's step, made of the same kernels the step-by-step loop calls with B = 1:
error (2) of the measured pose, the controller, error of the true pose, the record's rows, the
runner's divergence test, the plant's step; so a seed's record is bit for bit the one the
step-by-step loop gives (tests/test_segment.py).
"""

from __future__ import annotations

import numpy as np

from mlpfac.control.adaptive.kernels import AdaptiveState, adaptive_step, state_type
from mlpfac.control.law import law_step
from mlpfac.control.oracle import told_step
from mlpfac.jit import kernel
from mlpfac.loop.kernels import bad_seeds
from mlpfac.model import tracking_errors
from mlpfac.plants.mujoco.compiled import ROW, S_POSE, f1_at, f2_at, plant_step, robot_at, with_robot

BAD = -1  # the runner's test stopped the seed (a plant's own reasons are its codes, > 0)
ADAPTIVE = 0  # the controller's number for the adaptive scheme (the laws': mlpfac.control.law.KANAYAMA, ...)


def no_state() -> AdaptiveState:
    """The adaptive state a law's segment is given: no seed."""
    f = np.zeros((0, 0))
    return AdaptiveState(f, np.zeros((0, 0, 0)), f, np.zeros((0, 0, 0)), f, f, f, np.zeros(0), np.zeros(0, np.int64),
                         np.zeros(0), f, f)  # fmt: skip


@kernel()
def adaptive_row(s, first, e, v_r, omega_r, tele):
    """:func:`adaptive_step` for the one seed of ``s`` (an :class:`AdaptiveState`), its telemetry in
    the row ``tele``, packed as the runner records it: z (alpha, all of them; or max |z| when the
    row has room for one), trace P, mean diag P, the innovation (3), h_hat (3)."""
    adaptive_step(
        e, v_r, omega_r, first, s.z, s.P, s.S, s.H, s.u, s.innov, s.h_hat, s.trace, s.ints, s.params, s.R, s.Q
    )
    a = s.z.shape[1]
    o = tele.shape[0] - 8
    if o == a:
        for i in range(a):
            tele[i] = s.z[0, i]
    else:
        m = abs(s.z[0, 0])
        for i in range(1, a):
            x = abs(s.z[0, i])
            if x > m or x != x:  # a NaN wins, as in np.max
                m = x
        tele[0] = m
    tele[o], tele[o + 1] = s.trace[0], s.trace[0] / a
    for j in range(3):
        tele[o + 2 + j], tele[o + 5 + j] = s.innov[0, j], s.h_hat[0, j]


@kernel(
    lambda: with_robot(
        f"UniTuple(i8, 2)(i8, i8, f8[:, ::1], i8, f8[::1], f8[::1], f8, {', '.join(['f8[:, ::1]'] * 8)})",
        state_type(),
    ),
    ext="mujoco",
)
def segment(k0, k1, ref, law, c, told, limit, pose, pose_meas, e, e_true, u, ctele, ptele, draws, state, robot):
    """Steps k0 .. k1 - 1 of one seed. The controller: ``law`` (a law's number, with constants ``c``,
    and what an oracle is told, ``told``: :func:`mlpfac.control.oracle.told_step`; empty: the law
    itself), or ADAPTIVE, with the seed's ``state``, step 0 its first step. Records (N, ...) are written at
    row k; ``ctele``, ``ptele`` (N, W) the controller's and the plant's telemetry rows; ``draws``
    (k1 - k0, 3) the plant's noise; ``robot`` :meth:`~mlpfac.plants.mujoco.plant.MujocoPlant.kernel_args`.

    Returns (k, why): (k1, 0) when every step ran, else the step k at which the seed stopped and
    why (BAD: the runner's test, after the law; > 0: the plant's code, after the plant's step)."""
    st, hist = robot.st, robot.hist
    q, qm, ek, etk = np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 3))
    uk, sent, no_z, bad = np.empty((1, 2)), np.empty((1, 2)), np.empty((1, 0)), np.zeros(1, dtype=np.bool_)
    for k in range(k0, k1):
        r = ref[k]
        for j in range(3):
            q[0, j], qm[0, j] = st[S_POSE + j], hist[0, j]
        tracking_errors(qm, r, ek)
        z = no_z
        if law == ADAPTIVE:
            adaptive_row(state, k == 0, ek, r[3], r[4], ctele[k])
            uk[0, 0], uk[0, 1], z = state.u[0, 0], state.u[0, 1], state.z
        elif told.shape[0]:
            told_step(law, c, told, ek, r[3], r[4], sent, uk, ctele[k : k + 1])
        else:
            law_step(law, c, ek, r[3], r[4], uk, ctele[k : k + 1])
        tracking_errors(q, r, etk)
        for j in range(3):  # number by number: a row assignment compiles numba's shape-mismatch message
            pose[k, j], pose_meas[k, j], e[k, j], e_true[k, j] = q[0, j], qm[0, j], ek[0, j], etk[0, j]
        u[k, 0], u[k, 1] = uk[0, 0], uk[0, 1]
        if bad_seeds(q, uk, etk, z, limit, bad):
            return k, BAD
        why = plant_step(uk[0, 0], uk[0, 1], draws[k - k0], ptele[k], robot)
        if why:
            return k, why
    return k1, 0


# One step of many seeds, each at its own step k (mlpfac.envs.vector): each seed's arrays by address,
# a row of ``table`` (:func:`mlpfac.plants.mujoco.compiled.robot_row`, then (address, rows, columns) of each
# array below): the plant's telemetry row, the reference (N + 1, 5), the record's pose, measured pose,
# errors, true errors (N, 3) and commands (N, 2), the plant's telemetry rows (N, W), the loop's true
# and measured pose (1, 3), its errors and true errors of the step (1, 3), the true errors after the
# step (1, 3), the plant's noise draws (n, width).
(TELE_AT, REF_AT, POSE_AT, POSE_MEAS_AT, E_AT, E_TRUE_AT, U_AT, PTELE_AT, Q_AT, Q_MEAS_AT, E_STEP_AT, ET_STEP_AT,
 ET_NEXT_AT, DRAWS_AT) = (ROW + 3 * i for i in range(14))  # fmt: skip
WIDTH = ROW + 3 * 14


@kernel(
    "void(i8[::1], b1[::1], f8[:, ::1], b1[::1], f8[::1], i8[:, ::1], i8[::1], i8[::1], i8[::1], f8[:, ::1], "
    "f8[:, ::1], f8[:, ::1])",
    ext="mujoco",
)
def across(ks, active, U, observe, limit, table, drawn, stepping, codes, En, ETn, Rn):
    """Step ks[i] of each active seed i with its command U[i]: the closed loop's step
    (:meth:`~mlpfac.loop.closed_loop.ClosedLoop.command` then :meth:`~mlpfac.loop.closed_loop.ClosedLoop.actuate`,
    made of the same kernels, to the same bits), and where ``observe[i]`` the next step's errors (2)
    of the measured pose En[i] and of the true pose ETn[i], and its reference sample Rn[i]. ``drawn[i]``
    counts the seed's noise draws used; ``stepping[0]`` names the seed stepping (MuJoCo's warnings mark
    it). codes[i]: 0, BAD (the runner's test stopped it before its plant's step) or its plant's code."""
    no_z, bad, uk = np.empty((1, 0)), np.zeros(1, dtype=np.bool_), np.empty((1, 2))
    for i in range(ks.shape[0]):
        codes[i] = 0
        if not active[i]:
            continue
        t, k = table[i], ks[i]
        ref, q, qm = f2_at(t, REF_AT), f2_at(t, Q_AT), f2_at(t, Q_MEAS_AT)
        e, et, u = f2_at(t, E_STEP_AT), f2_at(t, ET_STEP_AT), f2_at(t, U_AT)
        pose, pose_meas, e_rec, et_rec = f2_at(t, POSE_AT), f2_at(t, POSE_MEAS_AT), f2_at(t, E_AT), f2_at(t, E_TRUE_AT)
        tracking_errors(q, ref[k], et)
        for j in range(3):
            pose[k, j], pose_meas[k, j], e_rec[k, j], et_rec[k, j] = q[0, j], qm[0, j], e[0, j], et[0, j]
        uk[0, 0], uk[0, 1] = U[i, 0], U[i, 1]
        u[k, 0], u[k, 1] = uk[0, 0], uk[0, 1]
        if bad_seeds(q, uk, et, no_z, limit[i], bad):
            codes[i] = BAD
            continue
        robot = robot_at(t)
        stepping[0] = i
        tele = f1_at(t, TELE_AT)
        why = plant_step(uk[0, 0], uk[0, 1], f2_at(t, DRAWS_AT)[drawn[i]], tele, robot)
        drawn[i] += 1
        ptele = f2_at(t, PTELE_AT)
        for j in range(tele.shape[0]):
            ptele[k, j] = tele[j]
        for j in range(3):
            q[0, j], qm[0, j] = robot.st[S_POSE + j], robot.hist[0, j]
        if why:
            codes[i] = why
        elif observe[i]:
            r, et_next = ref[k + 1], f2_at(t, ET_NEXT_AT)
            tracking_errors(qm, r, e)
            tracking_errors(q, r, et_next)
            for j in range(3):
                En[i, j], ETn[i, j] = e[0, j], et_next[0, j]
            for j in range(5):
                Rn[i, j] = r[j]
