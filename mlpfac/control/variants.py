"""The shipped controllers' names (:data:`CONTROLLERS`), and the named variants of the adaptive
controller (:class:`~mlpfac.control.adaptive.controller.AdaptiveConfig` fields, and :class:`~mlpfac.control.adaptive.networks.Networks`
fields under "networks"); :mod:`mlpfac.control.adaptive.controller` exports them. No imports of the package: the
controllers and the plug-in loader both read these names."""

from __future__ import annotations

# Named variants of the adaptive controller: AdaptiveConfig fields (and Networks fields under
# "networks") that override the scenario's [controller.adaptive] table. "adaptive" is the table as is.
# One variant per option alone, and "adaptive-best": the combination that measured best on the
# MuJoCo eight-* scenarios (the nominal prior, with forgetting so that it keeps adapting after an
# event, P bounded). The ablation table (docs/results-beyond.md) gives the figures and the command that made them.
# With no Q and no forgetting the EKF depends on P0 and R only through P0 / R.
VARIANTS: dict[str, dict] = {
    "adaptive": {},
    "adaptive-ukf": {"estimator": "ukf", "ukf_alpha": 0.1},
    "adaptive-cautious": {"cautious": 1.0},
    "adaptive-forget": {"forgetting": 0.9999, "P_max": 0.1},
    "adaptive-q": {"Q": 1e-8, "P_max": 0.1},
    "adaptive-prior": {"prior": True, "output_weight_std": 0.0, "P0": 1e-5, "R": 0.1},
    "adaptive-gains": {"learned_gains": True},
    "adaptive-best": {
        "prior": True,
        "output_weight_std": 0.0,
        "P0": 1e-5,
        "R": 0.1,
        "forgetting": 0.999,
        "P_max": 1e-4,
    },
}
# adaptive-best with the input gains learned from the measured motion (mlpfac.control.adaptive.input_model), re-adapted
# when a CUSUM on their innovation detects a change ("adaptive-input"), or by forgetting alone; and
# with a measurement delay of up to 6 steps found and predicted over ("adaptive-input-delay").
VARIANTS["adaptive-input"] = VARIANTS["adaptive-best"] | {"input_gains": True, "detect": 20.0}
VARIANTS["adaptive-input-forget"] = VARIANTS["adaptive-best"] | {"input_gains": True}
VARIANTS["adaptive-input-delay"] = VARIANTS["adaptive-input"] | {"input_delay": 6}
# the paper's scheme whose NN_f also sees the last command (the velocity state)
VARIANTS["adaptive-velocity"] = {"networks": {"velocity_inputs": True}}
# adaptive-input-delay on a real base: the certainty-equivalence law in Kanayama's structure, fed by
# h2, h5 (34) of the networks over the nominal prior, so that pose noise is not amplified as v_r falls,
# with one gain set for every robot (Ky = 150, Ktheta = 16: chosen on seeds 0-9 of the eight-* and
# tiago-* scenarios); the delay found by a bank of predictors (docs/real-robot-adaptive.md). A change
# of the input gains is detected also by a persistent bias of their innovation (detect_mean), the
# CUSUM's threshold raised to 50 beside it (fewer alarms on nominal runs); chosen on seeds 0-9 of the
# eight-*, cart-* and tiago-* scenarios.
VARIANTS["adaptive-real"] = VARIANTS["adaptive-input-delay"] | {
    "law_form": "kanayama",
    "law_gains": (10.0, 150.0, 16.0),
    "delay_finder": "bank",
    "detect": 50.0,
    "detect_mean": 20.0,
}
# adaptive-real with a channel that shows the bias reopened to a variance of 2e-2 (input_P_alarm)
# instead of input_P0: a wheel-radius or control-period change relearnt within a few steps, at a
# cost where the plant keeps changing (a friction change raises an alarm every half second).
VARIANTS["adaptive-real-fast"] = VARIANTS["adaptive-real"] | {"input_P_alarm": 2e-2}

# The shipped controllers of the torque level (mlpfac/control/dynamic.py): they command the wheels' torques.
TORQUE_LEVEL = ("fierro-lewis", "adaptive-dynamic", "oracle-dynamic")
# The model-predictive controllers with the run's own robot as their model (mlpfac/control/mpc/): they
# command the drive the robot has, (v, omega) to velocity servos, the wheels' torques to torque motors.
MPC_NAMES = ("mpc", "limit")
# The shipped policies (mlpfac/control/policy.py): an MLP trained off-line, its weights in policies/NAME.npz.
POLICIES = ("policy-dr",)
# Every shipped controller (the oracles: mlpfac/control/oracle.py); any other name is a plug-in's
# (or a policy's file, path/to/policy.npz).
CONTROLLERS = (*VARIANTS, "corradini", "kanayama", "oracle", "oracle-kanayama", *TORQUE_LEVEL, *MPC_NAMES, *POLICIES)
