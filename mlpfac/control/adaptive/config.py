"""The adaptive controller's options (:class:`AdaptiveConfig`): plain data, each value checked when
it is made (a bad one is a ConfigError naming its key); the controller that runs them is
:class:`mlpfac.control.adaptive.controller.Adaptive`, their named combinations :data:`mlpfac.control.variants.VARIANTS`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mlpfac.control.adaptive.networks import Networks
from mlpfac.exceptions import ConfigError
from mlpfac.tables import covariance


@dataclass(frozen=True)
class AdaptiveConfig:
    """The MLP-EKF scheme's choices; the paper fixes L_f, L_G and P0 only.

    The defaults are the paper's scheme with the project's tuned choices (docs/results-paper.md, "The
    project's defaults"; the paper's own numbers are sims/paper-faithful.toml). The options beyond the paper,
    each off by default:

    - ``estimator = "ukf"``: tune the weights with the square-root unscented filter
      (:class:`~mlpfac.control.adaptive.estimators.UKF`, spread ``ukf_alpha``, ``ukf_beta``, ``ukf_kappa``) instead of (29)-(32).
    - ``cautious = c > 0``: the cautious law (:meth:`~mlpfac.control.law.Law.cautious_control`) with the
      covariance of (h1, h2, h5, b_v, b_omega) from P_k, scaled by c; 0 is certainty equivalence.
    - ``Q``, ``forgetting``, ``P_max``: adaptation that does not switch off, with P bounded.
    - ``prior = true``: the networks learn only the correction to the nominal kinematic functions (5)-(6),
      f = f_nominal + NN_f, G = G_nominal + NN_G; the filter's measurement becomes
      e_k - f_nominal - G_nominal u_{k-1}. With zero output weights the scheme starts as Corradini's law.
    - ``learned_gains = true``: the law divides by the learned input gains b_v = -G_11, b_omega = -G_32
      (kept within ``GAIN_RANGE`` times T) instead of T, so a wrong actuator/wheel gain can be learned.
    - ``input_gains = true``: learn the plant's input gains g_v, g_omega from the motion measured
      between poses (:mod:`mlpfac.control.adaptive.input_model`) and send u / g, so the law's u reaches the robot as
      the kinematic model (7) assumes; ``input_P0``, ``input_forgetting``; ``detect = h > 0`` reopens
      their covariance when a CUSUM on the normalised innovation exceeds h (a change detected);
      ``detect_mean > 0`` also when a channel's leaky sum of innovations shows a bias, and
      ``input_P_alarm > 0`` reopens such a channel to that variance instead of ``input_P0``;
      ``input_delay = D > 0``: find a measurement delay of up to D control steps from the commands'
      correlation with the measured motion, and give the law the error of the pose predicted over it.
    - ``law_form = "kanayama"``: the certainty-equivalence law takes Kanayama's structure, with the
      estimates h2, h5 of (34) as its feedforward (:func:`~mlpfac.control.adaptive.kernels._law_kanayama`), with gains
      ``law_gains`` (Kx, Ky, Ktheta) (the scenario's Kanayama gains if unset); ``delay_finder
      = "bank"``: the delay by a bank of predictors over the candidate delays (:mod:`mlpfac.control.adaptive.delay_bank`).
    - ``output_weight_std``: the initial spread of the output-layer weights (``weight_std`` if unset);
      0 with ``prior`` starts from the nominal functions exactly.
    """

    networks: Networks = field(default_factory=Networks)
    P0: float = 0.1  # initial covariance P_0 = P0 I_alpha (the paper: 5)
    R: float | tuple[float, ...] | tuple[tuple[float, ...], ...] = (
        1e-3  # EKF measurement noise covariance, a tuning knob (the paper: 1e-6)
    )
    Q: float = 0.0  # EKF process noise, Q = Q I_alpha
    forgetting: float = 1.0  # P /= forgetting after each update (1: none)
    P_max: float | None = None  # cap on max diag P
    weight_std: float = 0.3  # initial weights ~ N(0, weight_std^2)
    output_weight_std: float | None = 0.01  # initial output-layer weights ~ N(0, .^2); None: weight_std
    estimator: str = "ekf"  # "ekf" (29)-(32) or "ukf" (square-root unscented)
    ukf_alpha: float = 1.0  # UKF sigma-point spread a: gamma = a sqrt(n + kappa), n the number of weights
    ukf_beta: float = 2.0  # UKF weight of the centre point in the covariance (2: Gaussian)
    ukf_kappa: float = 0.0  # UKF secondary spread
    cautious: float = 0.0  # weight c of the estimate covariance in the law (0: certainty equivalence)
    prior: bool = False  # learn the correction to the nominal kinematic functions
    learned_gains: bool = False  # divide by the learned input gains -G_11, -G_32 instead of T
    input_gains: bool = False  # learn the plant's input gains g_v, g_omega from the measured motion; send u / g
    input_delay: int = 0  # D > 0: find a measurement delay of up to D steps and predict the pose over it
    input_P0: float = 1e-4  # noqa: N815 -- the input gains' initial (and reopened) variance
    input_forgetting: float = 0.999  # the input gains' forgetting factor (1: none)
    detect: float = 0.0  # CUSUM threshold on the input gains' normalised innovation that reopens their P (0: off)
    detect_mean: float = 0.0  # > 0: also an alarm on a persistent bias of the innovation (0: off)
    input_P_alarm: float = 0.0  # noqa: N815 -- > 0: reopen a biased channel's P to this at an alarm (0: P0)
    law_form: str = "35"  # "35": the law (35); "kanayama": Kanayama's structure fed by (34)
    delay_finder: str = "correlation"  # how input_delay is found: "correlation" or "bank" (of predictors)
    law_gains: tuple[float, float, float] | None = None  # (Kx, Ky, Ktheta) of law_form "kanayama"; None: the scenario's

    def __post_init__(self) -> None:
        for name in ("P0", "weight_std", "ukf_alpha"):
            if not getattr(self, name) > 0:
                raise ConfigError(name, f"must be positive, got {getattr(self, name)}")
        if self.Q < 0:
            raise ConfigError("Q", f"a covariance must be non-negative, got {self.Q}")
        covariance(self.R, 3, "R")
        if not 0.0 < self.forgetting <= 1.0:
            raise ConfigError("forgetting", f"must be in (0, 1] (1: no forgetting), got {self.forgetting}")
        if self.P_max is not None and not self.P_max > 0:
            raise ConfigError("P_max", f"must be positive, got {self.P_max}")
        if self.output_weight_std is not None and not self.output_weight_std >= 0:
            raise ConfigError("output_weight_std", f"must be >= 0, got {self.output_weight_std}")
        if self.estimator not in ("ekf", "ukf"):
            raise ConfigError("estimator", f"choose 'ekf' or 'ukf', got {self.estimator!r}")
        if not self.cautious >= 0:
            raise ConfigError(
                "cautious", f"the caution weight must be >= 0 (0: certainty equivalence), got {self.cautious}"
            )
        if (
            isinstance(self.input_delay, bool)
            or not isinstance(self.input_delay, int)
            or not 0 <= self.input_delay <= 50
        ):
            raise ConfigError("input_delay", f"a whole number of control steps in 0-50, got {self.input_delay!r}")
        if not self.input_P0 > 0:
            raise ConfigError("input_P0", f"must be positive, got {self.input_P0}")
        if not 0.0 < self.input_forgetting <= 1.0:
            raise ConfigError("input_forgetting", f"must be in (0, 1] (1: none), got {self.input_forgetting}")
        if not self.detect >= 0:
            raise ConfigError("detect", f"the CUSUM threshold must be >= 0 (0: off), got {self.detect}")
        if not self.detect_mean >= 0:
            raise ConfigError("detect_mean", f"the bias threshold must be >= 0 (0: off), got {self.detect_mean}")
        if not 0 <= self.input_P_alarm < math.inf:
            raise ConfigError(
                "input_P_alarm", f"must be >= 0 and finite (0: reopen to input_P0), got {self.input_P_alarm}"
            )
        if self.detect_mean > 0 and not self.detect > 0:
            raise ConfigError("detect_mean", "the bias test raises the alarm of 'detect': set detect > 0 too")
        if self.input_P_alarm > 0 and not self.detect_mean > 0:
            raise ConfigError(
                "input_P_alarm", "a channel is reopened wide when the bias test sees it: set detect_mean > 0 too"
            )
        for name, allowed in (("law_form", ("35", "kanayama")), ("delay_finder", ("correlation", "bank"))):
            if getattr(self, name) not in allowed:
                raise ConfigError(name, f"choose one of {', '.join(map(repr, allowed))}, got {getattr(self, name)!r}")
        if self.law_gains is not None:
            g = self.law_gains
            if (
                not isinstance(g, list | tuple)
                or len(g) != 3
                or not all(isinstance(x, int | float) and not isinstance(x, bool) and 0 < x < math.inf for x in g)
            ):
                raise ConfigError("law_gains", f"three positive numbers (Kx, Ky, Ktheta), got {g!r}")
            object.__setattr__(self, "law_gains", tuple(float(x) for x in g))
        if self.law_form == "kanayama" and (self.estimator != "ekf" or self.cautious != 0 or self.learned_gains):
            raise ConfigError("law_form", "'kanayama' runs with estimator 'ekf', cautious 0 and learned_gains off")
        if self.prior and self.networks.residual:
            raise ConfigError("prior", "prior already adds e to f (f = f_nominal + NN_f); turn residual off")
