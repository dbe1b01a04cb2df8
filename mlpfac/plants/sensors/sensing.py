"""What the robot senses of its own pose: the ``[plant]`` keys of a pose source, checked, and what
the MuJoCo plant builds from them (the gyro added to its scene, the estimator's array, the seeded
streams of its noise).

``pose_source`` says where the pose the controller is given comes from:

- ``"truth"`` (the default): the simulated pose itself, plus ``pose_noise_std`` (a motion-capture
  system); exactly the runs of before.
- ``"odometry"``: dead reckoning from the driven wheels' encoders (their hinges' angles, quantized
  to ``encoder_cpr`` counts a revolution), with the nominal radius and track the IK uses; with
  ``gyro = true`` the heading from a gyro on the pose frame (MuJoCo's ``gyro`` sensor; white noise
  ``gyro_noise`` and a constant bias ``gyro_bias``, both rad/s).
- ``"fused"``: the same odometry corrected by absolute fixes of the pose (``fix_rate_hz``, taken
  ``fix_latency_s`` before they arrive, noise ``fix_noise_m``, ``fix_noise_rad``) in an EKF that
  applies each fix at the time it was taken and propagates again to now, and estimates the two
  wheels' scale factors (docs/equations.md).

The estimator itself is compiled (:mod:`mlpfac.plants.sensors.odometry`), inside the plant's control step.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.normal import Stream

SOURCES = ("truth", "odometry", "fused")
GYRO_MAX = 10.0  # rad/s of gyro noise or bias, at most (a gyro that bad is no gyro)
FIX_NOISE_MAX = 10.0  # m and rad of a fix's noise, at most
CPR_MAX = 10**9  # counts a revolution, at most
FIX_DEFAULTS = {"fix_rate_hz": 10.0, "fix_latency_s": 0.0, "fix_noise_m": 0.02, "fix_noise_rad": 0.02}
SENSOR_KEYS = ("pose_source", "encoder_cpr", "gyro", "gyro_noise", "gyro_bias", *FIX_DEFAULTS)
TRUTH_ONLY = ("pose_noise_std", "twist_noise_std", "wheel_speed_noise_std")  # noise of what "truth" gives


class Fixes(NamedTuple):
    rate_hz: float
    latency_s: float
    noise_m: float
    noise_rad: float


def check_sensing(config) -> None:
    """The pose-source keys of a ``[plant]`` table (``config``: a MujocoConfig), each refused in one
    line naming its key: an unknown source, a key that does nothing with the source chosen (a fix
    without fixes, a gyro's noise without a gyro, the truth's noise on another source), a value out
    of range."""
    src = config.pose_source
    if src not in SOURCES:
        raise ConfigError("pose_source", f"choose {' or '.join(map(repr, SOURCES))}, got {src!r}")
    cpr = config.encoder_cpr
    if cpr is not None and (isinstance(cpr, bool) or not isinstance(cpr, int) or not 1 <= cpr <= CPR_MAX):
        raise ConfigError(
            "encoder_cpr", f"expected a whole number of counts a revolution in 1 .. {CPR_MAX}, got {cpr!r}"
        )
    if not isinstance(config.gyro, bool):
        raise ConfigError("gyro", f"expected true or false, got {config.gyro!r}")
    for key in ("gyro_noise", "gyro_bias"):
        x = getattr(config, key)
        low = -GYRO_MAX if key == "gyro_bias" else 0.0
        if isinstance(x, bool) or not isinstance(x, int | float) or not low <= x <= GYRO_MAX:
            raise ConfigError(key, f"expected a number in {low:g} .. {GYRO_MAX:g} rad/s, got {x!r}")
    for key in FIX_DEFAULTS:
        x = getattr(config, key)
        if x is not None and (isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x)):
            raise ConfigError(key, f"expected a finite number, got {x!r}")
    if config.fix_rate_hz is not None and not config.fix_rate_hz > 0:
        raise ConfigError("fix_rate_hz", f"must be positive (fixes a second), got {config.fix_rate_hz!r}")
    if config.fix_latency_s is not None and config.fix_latency_s < 0:
        raise ConfigError(
            "fix_latency_s", f"must be >= 0 s (a fix arrives after it is taken), got {config.fix_latency_s!r}"
        )
    for key, unit in (("fix_noise_m", "m"), ("fix_noise_rad", "rad")):
        x = getattr(config, key)
        if x is not None and not 0 <= x <= FIX_NOISE_MAX:
            raise ConfigError(key, f"expected a standard deviation in 0 .. {FIX_NOISE_MAX:g} {unit}, got {x!r}")
    if src == "truth":
        given = [k for k in SENSOR_KEYS[1:] if getattr(config, k) not in (None, False, 0.0)]
        if given:
            raise ConfigError(
                given[0],
                'senses nothing with pose_source = "truth" (the pose itself is given): set pose_source = '
                '"odometry" or "fused"',
            )
        return
    for key in TRUTH_ONLY:
        if np.any(np.asarray(getattr(config, key), dtype=float) != 0):
            raise ConfigError(
                key,
                f'is the noise of what pose_source = "truth" gives; with {src!r} the pose and the motion come from '
                "the encoders, the gyro and the fixes: remove it, and set encoder_cpr, gyro_noise, fix_noise_m instead",
            )
    if not config.gyro and (config.gyro_noise or config.gyro_bias):
        raise ConfigError("gyro_noise" if config.gyro_noise else "gyro_bias", "needs a gyro: set gyro = true")
    if src == "odometry":
        given = [k for k in FIX_DEFAULTS if getattr(config, k) is not None]
        if given:
            raise ConfigError(given[0], 'takes fixes, which pose_source = "odometry" has none of: set "fused"')


def check_run(config, duration: float, T: float, where: str) -> None:
    """The fixes against the run (``duration``, control period ``T``): at most one a control step,
    and a latency shorter than the run. ``where`` names the ``[plant]`` table."""
    if config.pose_source != "fused":
        return
    f = fixes(config)
    if f.rate_hz > 1.0 / T * (1 + 1e-9):
        raise ConfigError(
            f"{where} fix_rate_hz",
            f"{f.rate_hz:g} Hz is more than one fix a control step (1 / T = {1 / T:g} Hz)",
        )
    if f.latency_s >= duration:
        raise ConfigError(
            f"{where} fix_latency_s",
            f"{f.latency_s:g} s is not shorter than the run ({duration:g} s): no fix would ever arrive",
        )


def fixes(config) -> Fixes:
    """The fixes of a ``"fused"`` source, the defaults where the table leaves a key unset."""
    return Fixes(*(float(v if (v := getattr(config, k)) is not None else d) for k, d in FIX_DEFAULTS.items()))


def described(config) -> str:
    """The pose source in words (the run's description, the viewer's text), '' for the truth."""
    src = config.pose_source
    if src == "truth":
        return ""
    enc = f"{config.encoder_cpr} counts a revolution" if config.encoder_cpr else "exact angles"
    heading = "the wheels"
    if config.gyro:
        heading = f"a gyro (noise {config.gyro_noise:g} rad/s, bias {config.gyro_bias:g} rad/s)"
    text = f"pose from odometry: wheel encoders ({enc}), heading from {heading}"
    if src == "fused":
        f = fixes(config)
        text += (
            f", fused in an EKF with fixes at {f.rate_hz:g} Hz arriving {f.latency_s:g} s late "
            f"(noise {f.noise_m:g} m, {f.noise_rad:g} rad); wheel scale factors estimated"
        )
    return text


# The estimator's process noise (docs/equations.md): what a real base's odometry is tuned with.
SLIP = 0.01  # std of each wheel's increment (and the gyro's), as a share of itself: slip, a radius off
Q_POSE = 1e-6  # m^2/s: a random walk of x and y beyond the wheels' (a skid, a sideways slide)
Q_HEADING = 1e-6  # rad^2/s: of theta
Q_SCALE = 3e-4  # 1/s: of each wheel's scale factor ("fused": a radius that changes, a load)
P0_POSE, P0_SCALE = 1e-8, 1e-2  # the start: known to 0.1 mm, 0.1 mrad; the wheels' scale to 10 %
GYRO_SENSOR = "mlpfac_gyro"


def add_gyro(spec, model, site: int) -> None:
    """MuJoCo's ``gyro`` sensor on the pose frame's site, added to ``spec`` (compiled by the caller):
    the base's angular velocity in the site's axes; its z is the heading rate on flat ground."""
    import mujoco

    name = model.site(site).name
    if not name:
        name = spec.sites[site].name = "mlpfac_pose_frame"
    spec.add_sensor(type=mujoco.mjtSensor.mjSENS_GYRO, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=name, name=GYRO_SENSOR)


class Sensing:
    """The estimator of one MuJoCo plant: its array (:mod:`mlpfac.plants.sensors.odometry`'s layout) made at
    each reset, and its seeded streams of noise."""

    def __init__(self, config, model, dofs, sign, radius: float, track: float, shortest_period: float) -> None:
        import mlpfac.plants.sensors.odometry as O  # noqa: N812

        self.config, self.fused = config, config.pose_source == "fused"
        self.qpos = [int(model.jnt_qposadr[model.dof_jntid[d]]) for d in dofs]
        self.sign = [float(x) for x in sign]
        self.gyro_adr = int(model.sensor_adr[model.sensor(GYRO_SENSOR).id]) + 2 if config.gyro else 0
        self.radius, self.track = float(radius), float(track)
        self.fixes = fixes(config) if self.fused else Fixes(0.0, 0.0, 0.0, 0.0)
        self.cap = math.ceil(self.fixes.latency_s / shortest_period + 1e-9) + 2 if self.fused else 0
        self.size = O.O_RING + self.cap * O.R_W

    def start(self, rng: np.random.Generator, qpos: np.ndarray, sensordata: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """The estimator's array at the start of a run: the robot knows where it starts (``pose``, at
        rest or moving); its encoders' counts start at a random phase of a count, drawn from its own
        stream. ``rng``: the plant's generator, whose own draws are left where they are."""
        import mlpfac.plants.sensors.odometry as O  # noqa: N812

        c = self.config
        enc, gyr, fix = rng.spawn(3)  # their own streams: the truth's pose noise stays as it was
        self.gyro = Stream(gyr if c.gyro and c.gyro_noise > 0 else None, 1)
        noisy = self.fixes.noise_m > 0 or self.fixes.noise_rad > 0
        self.fix = Stream(fix if self.fused and noisy else None, 3)
        s = np.zeros(self.size)
        q = 2.0 * math.pi / c.encoder_cpr if c.encoder_cpr else 0.0
        off = enc.random(2) if q else np.zeros(2)
        s[O.O_MODE], s[O.O_GYRO] = 2.0 if self.fused else 1.0, float(c.gyro)
        s[O.O_QL], s[O.O_QR], s[O.O_GADR], s[O.O_Q] = *self.qpos, self.gyro_adr, q
        s[O.O_OFFL], s[O.O_OFFR] = off
        s[O.O_GNOISE], s[O.O_GBIAS] = c.gyro_noise, c.gyro_bias
        s[[O.O_RATE, O.O_LAT, O.O_FNM, O.O_FNR]] = self.fixes
        s[O.O_R], s[O.O_B], s[O.O_SL], s[O.O_SR] = self.radius, self.track, *self.sign
        s[O.O_SLIP], s[O.O_QP], s[O.O_QTH] = SLIP, Q_POSE, Q_HEADING
        s[O.O_QS], s[O.O_CAP] = Q_SCALE if self.fused else 0.0, self.cap
        for i, side in enumerate((O.O_CL, O.O_CR)):
            phi = self.sign[i] * float(qpos[self.qpos[i]])
            s[side] = math.floor(phi / q + off[i]) if q else phi
        if c.gyro:
            s[O.O_GPREV] = float(sensordata[self.gyro_adr]) + c.gyro_bias + c.gyro_noise * self.gyro.take(1)[0, 0]
        s[O.O_NEXT], s[O.O_PEND] = 1.0, -1.0
        s[O.O_X : O.O_X + 3], s[O.O_X + 3 : O.O_X + 5] = pose, 1.0
        for i, p0 in enumerate((P0_POSE, P0_POSE, P0_POSE, P0_SCALE, P0_SCALE)):
            s[O.O_P + i * O.NX + i] = p0 if i < 3 or self.fused else 0.0
        if self.fused:  # step 0 in the ring
            s[O.O_RING : O.O_RING + O.NX + O.NX * O.NX] = s[O.O_X : O.O_X + O.NX + O.NX * O.NX]
        return s

    def draws(self, n: int) -> np.ndarray:
        """(n, 4) standard normals of the next n steps: the gyro's noise, a fix's noise (x, y, theta)."""
        return np.concatenate([self.gyro.take(n), self.fix.take(n)], axis=1)


class SensingPlant:
    """The pose source of the MuJoCo plant (its attributes are :class:`~mlpfac.plants.mujoco.plant.MujocoPlant`'s):
    ``_sensing`` (None for the truth) and the estimator's array ``_sense`` (empty for the truth:
    the compiled step's branch)."""

    def _build_sensing(self, config, r, periods: tuple[float, ...]) -> None:
        """The estimator of ``config``'s source for the robot ``r`` just read; with a gyro, the
        plant's scene compiled again with MuJoCo's gyro on its pose frame."""
        import mujoco

        self._sensing, self._sense = None, np.zeros(0)
        if config.pose_source == "truth":
            return
        if config.gyro:
            self._spec_nominal = spec = r.spec.copy()
            add_gyro(spec, r.model, r.site)
            self._spec, self.model = spec.copy(), spec.compile()
            self.data = mujoco.MjData(self.model)
        self._sensing = Sensing(config, self.model, r.dofs, r.sign, self.ik_radius, self.ik_track, min(periods))

    def _sensing_width(self) -> int:
        from mlpfac.plants.sensors.odometry import N_SENSE_TELE

        return 0 if self._sensing is None else N_SENSE_TELE

    def _sensing_telemetry(self, tele: np.ndarray, lo: int) -> dict[str, np.ndarray]:
        """The estimator's telemetry keys, views of ``tele`` from ``lo`` (:data:`mlpfac.plants.sensors.odometry.SENSE_TELEMETRY`)."""
        from mlpfac.plants.sensors.odometry import SENSE_TELEMETRY

        out = {}
        for key, w in SENSE_TELEMETRY if self._sensing is not None else ():
            out[key], lo = tele[lo : lo + w], lo + w
        return out
