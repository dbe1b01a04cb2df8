"""The adaptive MLP-EKF controller of the paper, composed of parts (estimator, nominal prior, law,
learned gains, input model), and its named variants. One run or a batch of seeds.

``step(e_k, r_k)`` takes the tracking error (2) and the reference sample
r_k = (x_r, y_r, theta_r, v_r, omega_r) and returns u_k = (v, omega).
"""

from __future__ import annotations

import numpy as np

from mlpfac.control.adaptive.config import AdaptiveConfig  # noqa: F401 -- exported here too
from mlpfac.control.adaptive.estimators import EKF, UKF
from mlpfac.control.baselines import Stepped
from mlpfac.control.law import GAIN_RANGE, Law
from mlpfac.control.variants import VARIANTS  # noqa: F401 -- exported here too (factory, scenario, controllers)
from mlpfac.jit import as_rows
from mlpfac.model import G_true, f_true, wrap
from mlpfac.normal import normal
from mlpfac.tables import covariance


class NominalPrior:
    """The nominal kinematic functions (5)-(6) under the networks: f = f_nominal + NN_f,
    G = G_nominal + NN_G; the filter's measurement is what they miss, e_k - f_nominal - G_nominal u_{k-1}."""

    @staticmethod
    def predict(e: np.ndarray, r: np.ndarray, u: np.ndarray, T: float) -> np.ndarray:
        return f_true(e, r[3], r[4], T) + np.einsum("jn,n->j", G_true(e, T), u)  # not BLAS

    @staticmethod
    def measurement(e: np.ndarray, e_nom: np.ndarray) -> np.ndarray:
        y = e - e_nom
        y[2] = wrap(y[2])
        return y

    @staticmethod
    def add(f: np.ndarray, G: np.ndarray, e: np.ndarray, r: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
        return f + f_true(e, r[3], r[4], T), G + G_true(e, T)


class Adaptive(Stepped):
    """The paper's scheme: NN_f, NN_G tuned by the EKF (29)-(32), used in (35) through (34).

    Composed of parts, chosen by :class:`AdaptiveConfig`: the estimator (the EKF, compiled, or the
    UKF), the nominal prior (or none), the law (certainty equivalence, or cautious with weight c),
    the input gains (T, or learned). The paper's parts, the EKF with the certainty-equivalence law
    and fixed gains, with or without the prior, run as one compiled kernel per step for all seeds
    (:func:`mlpfac.control.adaptive.kernels.adaptive_step`); the other compositions run numpy parts seed by seed.

    ``reset(T, rng)`` with one Generator: one run, ``step`` takes e (3,) and returns u (2,);
    with a sequence of B Generators: B seeds, e (B, 3) -> u (B, 2), telemetry (B, ...).
    """

    name = "adaptive"

    def __init__(
        self, law: Law, config: AdaptiveConfig, T: float, kanayama: tuple[float, float, float] = (10.0, 64.0, 16.0)
    ) -> None:
        """``kanayama``: the gains (Kx, Ky, Ktheta) of the law with ``law_form = "kanayama"``, unless the
        config's ``law_gains`` are given."""
        self.T = float(T)  # the control period the law and the networks' nominal prior are designed for
        self.kanayama = tuple(float(k) for k in (config.law_gains or kanayama))
        self.law = law
        self.config = config
        self.nets = config.networks
        self.labels = {"z": self.nets.labels(), "h_hat": ["h1", "h2", "h5"]}
        self.prior = NominalPrior() if config.prior else None
        self.caution = config.cautious
        self.learned_gains = config.learned_gains
        self.compiled = config.estimator == "ekf" and config.cautious == 0 and not config.learned_gains

    def _initial_weights(self, rng: np.random.Generator) -> np.ndarray:
        c, a = self.config, self.nets.alpha
        z0 = normal(rng, 0.0, c.weight_std, a)
        if c.output_weight_std is not None:  # rescale the same draws: the random stream does not change
            z0[self.nets.output_mask()] *= c.output_weight_std / c.weight_std
        return z0

    def _estimator(self, z0: np.ndarray) -> EKF | UKF:
        c, a = self.config, self.nets.alpha
        common = {
            "z0": z0,
            "P0": c.P0 * np.eye(a),
            "R": covariance(c.R, 3, "R"),
            "Q": c.Q * np.eye(a) if c.Q > 0 else None,
            "forgetting": c.forgetting,
            "P_max": c.P_max,
        }
        if c.estimator == "ukf":
            return UKF(**common, alpha=c.ukf_alpha, beta=c.ukf_beta, kappa=c.ukf_kappa)
        return EKF(**common)

    def reset(self, rng) -> None:
        from mlpfac.control.adaptive.input_model import (
            InputModel,  # the kernels: imported by a run, not by reading a scenario
        )
        from mlpfac.control.adaptive.kernels import adaptive_step, settings
        from mlpfac.jit import seeds

        rngs, self.single = seeds(rng)
        T = self.T
        z0 = np.stack([self._initial_weights(g) for g in rngs])  # (B, alpha)
        B, a = z0.shape
        self.first = True
        c = self.config
        self.input = None
        if c.input_gains or c.input_delay > 0:
            self.input = InputModel(
                B,
                T,
                c.input_gains,
                c.input_delay,
                c.input_P0,
                c.input_forgetting,
                c.detect,
                c.delay_finder == "bank",
                c.input_P_alarm,
                c.detect_mean,
            )
        if not self.compiled:
            self.seeds = [_NumpySeed(self, self._estimator(z0[b]), T) for b in range(B)]
            self.est = self.seeds[0].est if self.single else None  # one run: its estimator, for inspection
            self._tele = None
            return
        self.est = self._estimator(z0)  # the compiled EKF's state: z (B, alpha), P (B, alpha, alpha), C-ordered
        self.est.P = np.broadcast_to(c.P0 * np.eye(a), (B, a, a))
        Lf, LG = c.networks.L_f, c.networks.L_G
        nf = c.networks.n_f
        self._S = np.zeros((B, 11 + nf + Lf + LG))  # x_f, x_G, phi_f, phi_G, u_{k-1}, e_{k-1}, nominal e_k
        self._u, self._innovation, self._h_hat = np.zeros((B, 2)), np.zeros((B, 3)), np.zeros((B, 3))
        self._trace = np.zeros(B)
        self._H = np.zeros((B, 3, a))
        est, lim = self.est, self.law
        ints, params = settings(
            L_f=Lf, L_G=LG, residual=c.networks.residual, prior=self.prior is not None, has_Q=est.Q is not None,
            n_f=nf, kanayama=c.law_form == "kanayama", c=c.networks.error_scale, T=T, lambdas=lim.lambdas,
            v_max=np.inf if lim.v_max is None else lim.v_max,
            omega_max=np.inf if lim.omega_max is None else lim.omega_max,
            forgetting=est.forgetting,
            P_max=np.inf if est.P_max is None else est.P_max,
            kanayama_gains=self.kanayama,
        )  # fmt: skip
        Q = est.Q if est.Q is not None else np.zeros((1, 1))
        self._args = (est.z, est.P, self._S, self._H, self._u, self._innovation, self._h_hat, self._trace)
        self._consts = (ints, params, est.R, Q)
        self._tele = {"z": None, "trace_P": None, "mean_diag_P": None, "innovation": None, "h_hat": None}
        # load (or compile) the kernel now, not mid-run: zero seeds
        self._kernel = adaptive_step
        adaptive_step(np.zeros((0, 3)), 1.0, 0.0, True, *(x[:0] for x in self._args), *self._consts)

    def kernel_state(self, b: int):
        """Seed b's state for the compiled closed loop (:mod:`mlpfac.loop.compiled`), views of this
        controller's arrays, which it steps as :meth:`step` would from step 0; None unless the step
        is the one kernel (no input model) and the seeds are a batch."""
        from mlpfac.control.adaptive.kernels import AdaptiveState

        if not self.compiled or self.input is not None or self.single:
            return None
        # the order in which mlpfac.loop.compiled.adaptive_row packs them in a row
        assert list(self._tele) == ["z", "trace_P", "mean_diag_P", "innovation", "h_hat"]
        return AdaptiveState(*(x[b : b + 1] for x in self._args), *self._consts)

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        E = as_rows(e, 3)
        if self.input is not None:  # the input model's update; the error of the pose predicted over the delay
            E = self.input.observe(E, r, self.first)
        if not self.compiled:
            u = np.stack([s.step(E[b], r, self.first) for b, s in enumerate(self.seeds)])
        else:
            u = self._u
            self._kernel(E, float(r[3]), float(r[4]), self.first, *self._args, *self._consts)
        self.first = False
        if self.input is not None:  # the command sent: u / g
            u = self.input.command(u)
        return u[0].copy() if self.single else u

    def telemetry(self) -> dict[str, np.ndarray | float]:
        """z, trace P, mean diag P, the innovation (32) and h_hat (34) (and the input model's gains,
        delay and alarms); per seed, (B, ...), for a batch."""
        t = self._telemetry()
        if self.input is not None:
            t = t | {k: (v[0] if self.single else v) for k, v in self.input.telemetry().items()}
        return t

    def _telemetry(self) -> dict[str, np.ndarray | float]:
        if not self.compiled:
            per = [s.telemetry() for s in self.seeds]
            if self.single:
                return per[0]
            return {k: np.stack([np.asarray(p[k]) for p in per]) for k in per[0]}
        t, alpha = self._tele, self.nets.alpha
        if self.single:
            tr = float(self._trace[0])
            t["z"], t["trace_P"], t["mean_diag_P"] = self.est.z[0], tr, tr / alpha
            t["innovation"], t["h_hat"] = self._innovation[0], self._h_hat[0]
        else:
            t["z"], t["trace_P"], t["mean_diag_P"] = self.est.z, self._trace, self._trace / alpha
            t["innovation"], t["h_hat"] = self._innovation, self._h_hat
        return t

    @property
    def h_hat(self) -> np.ndarray:
        """h_hat (34) of the last step: (3,) for one run, (B, 3) for a batch."""
        h = np.stack([s.h_hat for s in self.seeds]) if not self.compiled else self._h_hat
        return h[0] if self.single else h

    def drop(self, b: int) -> None:
        """Seed b of a batch diverged: the numpy parts stop stepping it (the kernel's NaNs are harmless)."""
        if not self.compiled:
            self.seeds[b].dropped = True


class _NumpySeed:
    """One seed of the adaptive controller with numpy parts: the UKF, the cautious law, learned gains."""

    def __init__(self, ctrl: Adaptive, est: EKF | UKF, T: float) -> None:
        self.c, self.est, self.T = ctrl, est, T
        self.prev: tuple | None = None  # step k-1: x_f, x_G, e, u, nominal prediction of e_k, z, hidden layers
        self.innovation = np.zeros(3)
        self.h_hat = np.zeros(3)
        self.dropped = False

    def step(self, e: np.ndarray, r: np.ndarray, first: bool) -> np.ndarray:
        ctrl, nets, T = self.c, self.c.nets, self.T
        if self.dropped:
            return np.full(2, np.nan)
        if self.prev is not None:  # tune the weights with the error this step revealed, (28)-(32)
            x_f, x_G, e_prev, u_prev, e_nom, z_prev, head = self.prev
            y = e if ctrl.prior is None else ctrl.prior.measurement(e, e_nom)
            if isinstance(self.est, UKF):
                self.innovation = self.est.update(y, None, lambda Z: nets.h(Z, x_f, x_G, e_prev, u_prev))
            else:  # the hidden layers at z_k are last step's, unless something changed z since
                self.innovation = self.est.update(
                    y, lambda z: nets.h_and_jacobian(z, x_f, x_G, e_prev, u_prev, head if z is z_prev else None)
                )
        x_f, x_G = nets.inputs(e, r[3], r[4], self.prev[3] if self.prev is not None else np.zeros(2))
        z = self.est.z
        head = nets.head(z, x_f, x_G, e)
        u = self._control(e, r, x_f, x_G, head)
        e_nom = ctrl.prior.predict(e, r, u, T) if ctrl.prior is not None else None
        self.prev = (x_f, x_G, e, u, e_nom, z, head)
        return u

    def _control(self, e: np.ndarray, r: np.ndarray, x_f: np.ndarray, x_G: np.ndarray, head: tuple) -> np.ndarray:
        """(35) through (34) with the parts: nominal prior, learned input gains, cautious law.
        The Jacobians of the estimates are computed only for the cautious law, which uses them."""
        ctrl, T = self.c, self.T
        if ctrl.caution > 0:
            f, G, df, dG = ctrl.nets.jacobians(self.est.z, x_f, x_G, e, head)
        else:
            f, G = ctrl.nets.forward(self.est.z, x_f, x_G, e, head)
        if ctrl.prior is not None:
            f, G = ctrl.prior.add(f, G, e, r, T)
        theta = np.array([G[0, 1], f[0] - e[0], f[2] - e[2], T, T])  # h1, h2, h5 (34), b_v, b_omega
        if ctrl.learned_gains:
            lo, hi = GAIN_RANGE[0] * T, GAIN_RANGE[1] * T
            theta[3], theta[4] = np.clip(-G[0, 0], lo, hi), np.clip(-G[2, 1], lo, hi)
        self.theta, self.h_hat = theta, theta[:3]
        if ctrl.caution > 0:
            J = np.stack([dG[0, 1], df[0], df[2], np.zeros_like(df[0]), np.zeros_like(df[0])])  # (5, alpha)
            if ctrl.learned_gains:
                J[3], J[4] = -dG[0, 0], -dG[2, 1]
            return ctrl.law.cautious_control(e, theta, self.est.project(J), r[3], T, ctrl.caution)
        if ctrl.learned_gains:
            return ctrl.law.cautious_control(e, theta, None, r[3], T, 0.0)
        return ctrl.law.control(e, self.h_hat, r[3], T)

    def telemetry(self) -> dict[str, np.ndarray | float]:
        trace = float(self.est.diag_P().sum())
        return {
            "z": self.est.z,
            "trace_P": trace,
            "mean_diag_P": trace / self.c.nets.alpha,  # what np.mean computes, to the bit
            "innovation": self.innovation,
            "h_hat": self.h_hat,
        }
