"""A MuJoCo robot as a prediction model: its control step run from any state, many times, compiled.

A model-predictive controller (:mod:`mlpfac.control.mpc`) plans with the run's own robot: a
:class:`~mlpfac.plants.mujoco.plant.MujocoPlant` built from the scenario as the run's is (its compiled
model, its world, its forces' schedule, its drive), told each event at its time. :class:`Predictor`
steps that plant's compiled control step (:func:`mlpfac.plants.mujoco.compiled.plant_step`: the IK or the
torque drive, the physics, the terrain, the force of the step) from a state it is given, without
noise, so a prediction is what the robot would do, to the bit, from that state:

- :meth:`Predictor.rollouts`: R control sequences (R, H, 2) from one state, each step's tracking
  error (2) to the reference;
- :meth:`Predictor.transition`: one control step, and its Jacobian in the state's tangent space by
  forward differences (the state's positions moved along each velocity direction with
  ``mj_integratePos``, as ``mjd_transitionFD`` moves them, through the whole control step rather
  than one physics step);
- :meth:`Predictor.pose_jacobian`: the pose (x, y, theta) of a state and its Jacobian
  (``mj_jacSite``).

A state is MuJoCo's ``mjSTATE_INTEGRATION`` (everything ``mj_step`` reads: time, positions,
velocities, actuator states, the solver's warm start, controls, applied forces, mocap bodies) with
the plant's own step state (the unwrapped heading, the drive's integrals) and the world's step
counter (which row of the force schedule comes next). Every rollout restores it with
``mj_setState`` and ``mj_step1`` (the derived quantities of that state, as the plant has them
between control steps), so its bits do not depend on what ran before it. One thread, no BLAS: the
same bits on every machine.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.jit import built, kernel
from mlpfac.plants.mujoco import compiled as K  # noqa: N812 - the kernel's layout constants
from mlpfac.plants.mujoco.compiled import N_ST, S_POSE, S_THETA, plant_step, with_robot
from mlpfac.plants.world.terrain import W_STEP

STATE = int(mujoco.mjtState.mjSTATE_INTEGRATION)
FAILED = 1.0e6  # the error (m, rad) a rollout records from the step its robot diverged on

if built("mujoco") is None:
    from numba import types

    _P = types.intp
    mj_setState = types.ExternalFunction(  # noqa: N816 - MuJoCo's name
        "mj_setState", types.void(_P, _P, _P, types.uint32)
    )
    mj_integratePos = types.ExternalFunction(  # noqa: N816
        "mj_integratePos", types.void(_P, _P, _P, types.float64)
    )
    mj_differentiatePos = types.ExternalFunction(  # noqa: N816
        "mj_differentiatePos", types.void(_P, _P, types.float64, _P, _P)
    )
    mj_jacSite = types.ExternalFunction("mj_jacSite", types.void(_P, _P, _P, _P, types.int32))  # noqa: N816
    mj_step1, mj_getState = K.mj_step1, K.mj_getState  # noqa: N816


@kernel()
def _restore(x, st, w, robot):
    """The robot at state ``x`` (mjSTATE_INTEGRATION), step state ``st`` and world step ``w``, its
    derived quantities computed (``mj_step1``)."""
    mj_setState(robot.mp, robot.dp, x.ctypes.data, STATE)
    for i in range(N_ST):
        robot.st[i] = st[i]
    robot.st[K.S_WARN] = 0.0
    if robot.world.shape[0]:
        robot.world[W_STEP] = w
    mj_step1(robot.mp, robot.dp)


@kernel()
def _capture(x, st, robot):
    mj_getState(robot.mp, robot.dp, x.ctypes.data, STATE)
    for i in range(N_ST):
        st[i] = robot.st[i]


@kernel()
def _error(st, r, e):
    """The tracking error (2) of the pose in ``st`` to the reference sample ``r``."""
    th = st[S_POSE + 2]
    c, s = cos(th), sin(th)
    dx, dy = r[0] - st[S_POSE], r[1] - st[S_POSE + 1]
    e[0] = c * dx + s * dy
    e[1] = -s * dx + c * dy
    e[2] = math.pi - ((math.pi - (r[2] - th)) % (2.0 * math.pi))


@kernel(
    lambda: with_robot(
        "void(f8[::1], f8[::1], f8, f8[:, :, ::1], f8[:, ::1], i8, f8[:, :, ::1], f8[::1], i8[::1], f8[:, ::1], f8[:, ::1])"
    ),
    ext="mujoco",
)
def rollouts(x, st, w, U, ref, k, E, tele, first, X, ST, robot):
    """R control sequences U (R, H, 2) from the state (x, st, w) at control step k: E (R, H, 3) the
    tracking error (2) after each step j to ``ref[k + j + 1]`` (the last row held beyond the end);
    from the step a rollout's robot diverges on, FAILED. ``tele``: the step's telemetry (scratch).

    The first row's states after each step are kept in X (H, nx) and ST (H, N_ST + 1: the step
    state and the world's step). Row i's commands equal the first row's before step ``first[i]``:
    it starts from the first row's state there, its errors before it the first row's (the same bits
    as from the start). ``first[0]`` = -1: the first row is not run, its errors in E[0] and its
    states in X, ST already (the same state and commands as a rollout before)."""
    R, H = U.shape[0], U.shape[1]
    last = ref.shape[0] - 1
    draw = np.zeros(3)
    for i in range(R):
        f = first[i]
        if f < 0:
            continue
        dead = False
        if f == 0:
            _restore(x, st, w, robot)
        else:
            for j in range(f):
                for c in range(3):
                    E[i, j, c] = E[0, j, c]
            if f == H:
                continue
            if E[0, f - 1, 0] == FAILED:
                dead = True
            else:
                _restore(X[f - 1], ST[f - 1, :N_ST], ST[f - 1, N_ST], robot)
        for j in range(f, H):
            if not dead and plant_step(U[i, j, 0], U[i, j, 1], draw, tele, robot) != 0:
                dead = True
            if dead:
                E[i, j, 0], E[i, j, 1], E[i, j, 2] = FAILED, FAILED, FAILED
            else:
                _error(robot.st, ref[min(k + j + 1, last)], E[i, j])
                if i == 0:
                    _capture(X[j], ST[j, :N_ST], robot)
                    ST[j, N_ST] = robot.world[W_STEP] if robot.world.shape[0] else 0.0


@kernel(
    lambda: with_robot("i8(f8[::1], f8[::1], f8, f8, f8, f8, i8[::1], f8[::1], f8[::1], f8[:, ::1], f8[::1])"),
    ext="mujoco",
)
def transition(x, st, w, u0, u1, eps, S, x1, st1, A, tele, robot):
    """One control step of u = (u0, u1) from (x, st, w): the next state into (x1, st1) and, when A
    is (len(S), len(S)), its Jacobian among the tangent directions S (indices into positions 0..nv-1
    and velocities nv..2nv-1) by forward differences of ``eps`` (positions moved with
    ``mj_integratePos``, the next states compared with ``mj_differentiatePos``). Returns the plant's
    divergence code of the unperturbed step."""
    draw = np.zeros(3)
    nv = robot.qvel.shape[0]
    _restore(x, st, w, robot)
    why = plant_step(u0, u1, draw, tele, robot)
    _capture(x1, st1, robot)
    if A.shape[0] == 0 or why != 0:
        return why
    q1 = robot.qpos.copy()
    v1 = robot.qvel.copy()
    dq = np.zeros(nv)
    for j in range(S.shape[0]):
        col = S[j]
        _restore(x, st, w, robot)
        if col < nv:
            dq[:] = 0.0
            dq[col] = 1.0
            mj_integratePos(robot.mp, robot.qpos.ctypes.data, dq.ctypes.data, eps)
        else:
            robot.qvel[col - nv] += eps
        mj_step1(robot.mp, robot.dp)
        plant_step(u0, u1, draw, tele, robot)
        mj_differentiatePos(robot.mp, dq.ctypes.data, 1.0, q1.ctypes.data, robot.qpos.ctypes.data)
        for i in range(S.shape[0]):
            row = S[i]
            A[i, j] = (dq[row] if row < nv else robot.qvel[row - nv] - v1[row - nv]) / eps
    return why


@kernel(lambda: with_robot("void(f8[::1], f8[::1], f8, f8[::1], f8[::1], f8[::1])"), ext="mujoco")
def correct(x, st, w, dx, x1, st1, robot):
    """The state (x, st) moved by the tangent vector dx (2 nv: positions with ``mj_integratePos``,
    velocities added), its pose read again (the heading unwrapped from st's): into (x1, st1)."""
    nv = robot.qvel.shape[0]
    _restore(x, st, w, robot)
    dq = np.empty(nv)
    for i in range(nv):
        dq[i] = dx[i]
    mj_integratePos(robot.mp, robot.qpos.ctypes.data, dq.ctypes.data, 1.0)
    for i in range(nv):
        robot.qvel[i] += dx[nv + i]
    mj_step1(robot.mp, robot.dp)
    K.read_pose(robot.site_xpos, robot.site_xmat, robot.st)
    _capture(x1, st1, robot)


@kernel(lambda: with_robot("void(f8[::1], f8[::1], f8, f8[:, ::1])"), ext="mujoco")
def pose_jacobian(x, st, w, Hx, robot):
    """The pose's Jacobian Hx (3, 2 nv) at the state: d(x, y) of the pose frame's site, and d(theta)
    of its heading atan2(R10, R00) for the site's rotation w (world axes, ``mj_jacSite``): with R's
    first column c, dc = w x c, so dtheta = w_z - R20 (R00 w_x + R10 w_y) / (R00^2 + R10^2) (the
    heading of a frame tilted off the floor turns with its roll and pitch too). The velocities': zero."""
    nv = robot.qvel.shape[0]
    _restore(x, st, w, robot)
    jacp = np.zeros(3 * nv)
    jacr = np.zeros(3 * nv)
    mj_jacSite(robot.mp, robot.dp, jacp.ctypes.data, jacr.ctypes.data, robot.ints[K.I_SITE])
    for i in range(3):
        for j in range(Hx.shape[1]):
            Hx[i, j] = 0.0
    R = robot.site_xmat
    flat = R[0] * R[0] + R[3] * R[3]
    for j in range(nv):
        wx, wy, wz = jacr[j], jacr[nv + j], jacr[2 * nv + j]
        Hx[0, j], Hx[1, j] = jacp[j], jacp[nv + j]
        Hx[2, j] = wz - R[6] * (R[0] * wx + R[3] * wy) / flat


class Predictor:
    """The robot ``plant`` (a :class:`~mlpfac.plants.mujoco.plant.MujocoPlant` that no run steps) as a
    model: states captured from it or from another robot of the same model, stepped from any of
    them. Told an event (:meth:`apply`), it is the robot after the event."""

    def __init__(self, plant) -> None:
        self.plant = plant
        self.control_steps = 0  # control steps the model has taken (benchmarks/bench_mpc.py)
        self._X, self._ST = np.empty((0, 0)), np.empty((0, 0))  # the last rollout's first row's states
        self._last: tuple | None = None  # ... and what it was of: (k, ref, x, st, its commands, its errors)
        self._sizes()

    def _sizes(self) -> None:
        p = self.plant
        m = p.model
        self.nx = mujoco.mj_stateSize(m, STATE)
        self.nv = int(m.nv)
        # the directions an estimator estimates: the positions (in the tangent space), then the
        # velocities, of every degree of freedom but the chassis' height, roll and pitch (the free
        # joint's third to fifth), which the pose does not see: the model carries them from the
        # wheels' contacts
        unseen = {p._droot + 2, p._droot + 3, p._droot + 4}
        dofs = [i for i in range(self.nv) if i not in unseen]
        self.S = np.array(dofs + [self.nv + i for i in dofs], dtype=np.int64)
        self.n, self.half = len(self.S), len(dofs)
        self._velocity_index = {dof: self.half + i for i, dof in enumerate(dofs)}
        self._tele = np.zeros(p.tele.shape[0])

    @property
    def world_step(self) -> bool:
        """Whether the model's world counts its steps (a force's schedule)."""
        return self.plant._push.shape[0] > 0

    def capture(self, plant=None) -> tuple[np.ndarray, np.ndarray]:
        """The state (x, st) of ``plant`` (a robot of this model, the run's own) or of the model."""
        p = plant or self.plant
        x = np.empty(self.nx)
        mujoco.mj_getState(p.model, p.data, x, STATE)
        return x, p.st.copy()

    def args(self):
        """The model as the kernels take it; MuJoCo's warnings during its steps are its own."""
        K.watch(self.plant.st)
        return self.plant._args

    def rollouts(self, x, st, k: int, U: np.ndarray, ref: np.ndarray, E: np.ndarray) -> None:
        """:func:`rollouts` of U (R, H, 2) from (x, st) at step k into E (R, H, 3). A row whose
        commands begin as the first row's starts where they part; the first row is not run again
        when the rollout before was of the same state, step, reference and commands (its errors and
        states kept): the same bits, fewer steps."""
        R, H = U.shape[0], U.shape[1]
        parted = np.any(U[0] != U, axis=2)  # (R, H): a row's commands not the first row's (exact: no arithmetic)
        first = np.where(parted.any(axis=1), parted.argmax(axis=1), H)
        first[0] = 0
        last = self._last
        if (
            last is not None
            and last[0] == k
            and last[1] is ref
            and np.array_equal(last[2], x)
            and np.array_equal(last[3], st)
            and np.array_equal(last[4], U[0])
        ):
            E[0] = last[5]
            first[0] = -1
        elif self._X.shape[0] != H:
            self._X, self._ST = np.empty((H, self.nx)), np.empty((H, N_ST + 1))
        rollouts(x, st, float(k), U, ref, k, E, self._tele, first, self._X, self._ST, self.args())
        self._last = (k, ref, x.copy(), st.copy(), U[0].copy(), E[0].copy())
        self.control_steps += R * H - int(np.maximum(first, 0).sum()) - (H if first[0] < 0 else 0)

    def transition(self, x, st, k: int, u, eps: float, A: np.ndarray):
        x1, st1 = np.empty(self.nx), np.empty(N_ST)
        why = transition(x, st, float(k), float(u[0]), float(u[1]), eps, self.S, x1, st1, A, self._tele, self.args())
        self.control_steps += 1 + A.shape[0]
        return x1, st1, int(why)

    def correct(self, x, st, k: int, dx: np.ndarray):
        """(x, st) moved by dx along the estimated directions S."""
        full = np.zeros(2 * self.nv)
        full[self.S] = dx
        x1, st1 = np.empty(self.nx), np.empty(N_ST)
        correct(x, st, float(k), full, x1, st1, self.args())
        return x1, st1

    def wheel_rows(self, x) -> tuple[np.ndarray, np.ndarray]:
        """The wheels' speeds (left, right; forward positive) as a measurement of the state x: their
        Jacobian (2, 2 nv) in the tangent space and their values."""
        p = self.plant
        nq = int(p.model.nq)
        Hw, w = np.zeros((2, self.n)), np.empty(2)
        for i, (dof, sign) in enumerate(zip(p.robot.dofs, p.robot.sign, strict=True)):
            Hw[i, self._velocity_index[dof]] = sign
            w[i] = sign * x[1 + nq + dof]
        return Hw, w

    def pose_jacobian(self, x, st, k: int) -> np.ndarray:
        """The pose's Jacobian (3, n) along the estimated directions S."""
        Hx = np.zeros((3, 2 * self.nv))
        pose_jacobian(x, st, float(k), Hx, self.args())
        return np.ascontiguousarray(Hx[:, self.S])

    def apply(self, event, x, st) -> tuple[np.ndarray, np.ndarray]:
        """Tell the model ``event`` with the robot at (x, st): the state after it (an event that
        stands the robot on new wheels moves it), in the changed model's layout."""
        p = self.plant
        mujoco.mj_setState(p.model, p.data, x, STATE)
        p.st[:] = st
        mujoco.mj_forward(p.model, p.data)
        p.apply(event)
        self._last = None  # a rollout before is of another robot
        self._sizes()
        return self.capture()

    @staticmethod
    def heading(st: np.ndarray) -> float:
        return float(st[S_THETA])
