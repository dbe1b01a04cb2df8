"""Closed-loop runs on the kinematic plant: determinism, boundedness, divergence, metrics."""

import json
import math

import numpy as np
import pytest

from mlpfac.loop.metrics import metrics
from mlpfac.loop.runner import run
from mlpfac.scenario.parse import load, parse


def test_same_seed_gives_bit_identical_runs():
    scn = load("paper").with_overrides(duration=3.0, seed=7)
    a, b = run(scn), run(scn)
    for name in ("pose", "pose_meas", "e", "u"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(a.ctrl["z"], b.ctrl["z"])
    c = run(scn.with_overrides(seed=8))
    assert not np.array_equal(a.ctrl["z"], c.ctrl["z"])


@pytest.mark.parametrize("seed", [0, 1])
def test_paper_scenario_stays_bounded(seed):
    rec = run(load("paper").with_overrides(seed=seed))
    m = metrics(rec)
    assert m["status"] == "ok", m["reason"]
    assert m["phases"]["after"]["rms_position_error_m"] < 0.05
    assert m["max_abs_weight"] < 50
    assert [ev["kind"] for ev in m["events"]] == ["control_period"]
    json.dumps(m)  # serialisable


def test_corradini_with_true_functions_and_no_noise_is_exact():
    """No noise, no model change: e1 decays as lambda_1^k on the plant itself."""
    table = {
        "duration": 0.5,
        "plant": {"kind": "kinematic", "noise_cov": 0.0},
        "initial": {"error": [0.1, 0.0, 0.0]},
        "controller": {"name": "corradini", "lambdas": [0.7, 0.8, 0.8], "v_max": math.inf, "omega_max": math.inf},
    }
    rec = run(parse(table))
    np.testing.assert_allclose(rec.e_true[:, 0], 0.1 * 0.7 ** np.arange(rec.n), rtol=1e-9, atol=1e-14)


def test_a_diverging_run_keeps_its_record():
    table = {
        "duration": 2.0,
        "divergence_m": 0.05,
        "initial": {"error": [0.0, 0.0, 0.0]},
        "controller": {"name": "adaptive", "adaptive": {"P0": 5.0, "R": 1e-6, "weight_std": 1.0}},
    }
    rec = run(parse(table))
    m = metrics(rec)
    assert m["status"] == "diverged" and "position error" in m["reason"]
    assert 0 < rec.n < len(rec.t)
    assert np.all(np.isfinite(rec.pose[: rec.n])) and np.all(np.isnan(rec.pose[rec.n :]))
    assert m["steps"] == rec.n


def test_phases_exclude_the_warmup_and_split_at_the_event():
    m = metrics(run(load("paper").with_overrides(controller="corradini")))
    assert m["excluded_s"] == [0.0, 2.0]
    assert m["phases"]["before"]["start_s"] == 2.0 and m["phases"]["before"]["end_s"] == 12.5
    assert m["phases"]["after"]["start_s"] == 12.5 and m["phases"]["after"]["end_s"] == 25.0
    assert m["max_abs_weight"] is None


def test_a_scenario_without_events_has_one_phase():
    m = metrics(run(parse({"duration": 3.0, "controller": {"name": "kanayama"}})))
    assert list(m["phases"]) == ["before"] and m["phases"]["before"]["end_s"] == 3.0


def test_the_public_api_is_small_and_lazy():
    """``import mlpfac`` imports no numpy; every name in __all__ resolves; the README's example runs."""
    import subprocess
    import sys

    code = "import sys, mlpfac; assert 'numpy' not in sys.modules; [getattr(mlpfac, n) for n in mlpfac.__all__]"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).returncode == 0
    import mlpfac

    scn = mlpfac.load("eight-payload").with_overrides(controller="kanayama", seed=4, duration=0.5)
    m = mlpfac.metrics(mlpfac.run(scn))
    assert m["status"] == "ok" and m["controller"] == "kanayama" and m["seed"] == 4
