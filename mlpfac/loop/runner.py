"""The closed loop: reference -> error (2) -> controller -> plant, one run or a batch of seeds -> RunRecords."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mlpfac.control.baselines import Stepped
from mlpfac.io.interrupts import Terminated
from mlpfac.loop.closed_loop import ClosedLoop
from mlpfac.loop.factory import make_controller, make_plant
from mlpfac.loop.record import RunRecord
from mlpfac.plants.base import Plant
from mlpfac.scenario.parse import Scenario
from mlpfac.scenario.reference import sample_rates


@dataclass
class Built:
    """What a run needs before its first step: the reference (its rates where it gives them, and
    where it stops being finite), the plant and the controller."""

    ref: np.ndarray
    plant: Plant
    ctrl: Stepped
    rates: np.ndarray | None = None
    end: tuple[int, str] | None = None


def reference(scn: Scenario) -> tuple[np.ndarray, np.ndarray | None, tuple[int, str] | None]:
    """The reference at every step's time (N + 1, 5), its rates (N + 1, 2) where it gives them, and
    (step, why) where it is first not finite (a reference class of the user's), else None."""
    ref, rates = sample_rates(scn.reference, np.arange(scn.steps + 1) * scn.T)
    bad = ~np.isfinite(ref[: scn.steps]).all(axis=1)
    if not bad.any():
        return ref, rates, None
    k = int(np.argmax(bad))
    why = getattr(scn.reference, "why", None)
    return ref, rates, (k, (why(k * scn.T) if why else "") or "the reference is not finite")


def build(scn: Scenario, instance: object | None = None) -> Built:
    """Sample the reference, build the plant and the controller: what can fail (a bad model, a
    missing actuator) fails here, before a run writes or sends anything. ``instance``: an object of
    the scenario's plug-in controller to run (:func:`mlpfac.loop.factory.make_controller`)."""
    ref, rates, end = reference(scn)
    plant = make_plant(scn, ref)
    return Built(ref, plant, make_controller(scn, instance, plant), rates, end)


def run(
    scn: Scenario, sink=None, on_step: Callable[[int], None] | None = None, built: Built | None = None
) -> RunRecord:
    """Run ``scn`` once. Returns the record; status "diverged" or "interrupted" keeps what was recorded.

    ``sink`` (see :mod:`mlpfac.log`) receives the record every ``FLUSH_EVERY`` steps and at the end,
    also after a divergence, a Ctrl-C or a SIGTERM (the reason says "interrupted" or "terminated").
    ``built``: from :func:`build`, used once (the plant and the controller keep state).
    ``on_step(k)`` is called after every step k; the loop then goes step by step in Python. Without
    it, a MuJoCo plant with Kanayama's or Corradini's law, or an oracle told them, runs compiled from
    one event or flush to the next (:mod:`mlpfac.loop.compiled`), to the same bits.
    A run is the closed loop of :func:`run_batch` with one seed (B = 1).
    """
    built = built or build(scn)
    return _loop([scn], built.ref, built.plant, built.ctrl, sink, on_step, True, built.rates, built.end)[0]


def same_but_seed(scns: list[Scenario]) -> bool:
    t0 = {k: v for k, v in scns[0].table.items() if k != "seed"}
    return all({k: v for k, v in s.table.items() if k != "seed"} == t0 for s in scns[1:])


def run_batch(scns: list[Scenario], plant_list: bool = False) -> list[RunRecord]:
    """Run seeds of one scenario together, one record per scenario, each equal to ``run(scn)``.

    ``scns`` must differ in their seed only (ValueError otherwise). Every controller and variant
    runs batched: the compiled controllers step all seeds in one kernel call per step, the numpy
    parts (UKF, cautious law, learned gains) seed by seed; the kinematic plant is batched, any
    other plant (MuJoCo) is one object per seed (``plant_list`` forces that for the kinematic one
    too). Each seed's arithmetic does not depend on the others, so its record is its B = 1 run's
    to the last bit (tests/test_batch.py). A seed that diverges stops recording there; the others
    go on. Weights are recorded as max |z| per step (what :func:`metrics` reads), not all alpha
    of them. ``wall_time_s`` is the batch's wall time / B. KeyboardInterrupt propagates: an
    interrupted batch has no whole run.
    """
    if not scns:
        return []
    if not same_but_seed(scns):
        raise ValueError("run_batch needs scenarios that differ in their seed only")
    base = scns[0]
    ref, rates, end = reference(base)
    plant = make_plant(base, ref)
    if plant_list or not plant.batched:
        plant = [plant] + [make_plant(s, ref) for s in scns[1:]]
    recs = _loop(scns, ref, plant, make_controller(base, None, plant[0] if isinstance(plant, list) else plant), None,
                 None, False, rates, end)  # fmt: skip
    if any(r.status == "interrupted" for r in recs):
        raise KeyboardInterrupt
    return recs


def _loop(scns, ref, plant, ctrl: Stepped, sink, on_step, full: bool, rates=None, end=None) -> list[RunRecord]:
    """The closed loop for B = len(scns) seeds of one scenario. ``full``: record every weight (else
    max |z| per step). A list of plants, or a plant without a batch form, steps one per seed."""
    loop = ClosedLoop(scns, ref, plant, ctrl, full, on_step is None, rates, end)
    wall0 = time.perf_counter()
    if sink is not None:
        sink.begin(loop.recs[0], geometry=loop.geometry(), ref_path=ref[: loop.N if end is None else end[0]])
    try:
        if loop.compiled:
            loop.run_segments(sink)
        else:
            loop.run_steps(sink, on_step)
    except KeyboardInterrupt as err:
        loop.interrupted("terminated by SIGTERM" if isinstance(err, Terminated) else "interrupted")
    finally:
        loop.finish((time.perf_counter() - wall0) / loop.B)
        if sink is not None:
            sink.end(loop.recs[0])
    return loop.recs
