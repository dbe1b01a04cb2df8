"""The text panel: what the run is, which controller, what the event is, and where to look.

Written when the run starts (scenario, controller, events to come) and again when it ends, with
the figures that say where to look, measured from the record itself.
"""

from __future__ import annotations

import numpy as np

from mlpfac.loop.metrics import RunMetrics, metrics, outcome_words
from mlpfac.loop.record import RunRecord

CONTROLLERS = {
    "adaptive": "the paper's scheme: MLPs learn f and G, an EKF tunes their weights",
    "corradini": "the law (35) given the nominal h, no learning",
    "kanayama": "Kanayama's kinematic law, no learning",
    "oracle": "the law (35) given the plant's true functions",
    "oracle-kanayama": "Kanayama's law told the plant's changes (the true radius, period and delay)",
    "fierro-lewis": "wheel torques: Kanayama's law backstepped through computed torque with the nominal dynamic model",
    "adaptive-dynamic": "wheel torques: fierro-lewis with MLPs and an EKF learning the dynamic model's error",
    "oracle-dynamic": "wheel torques: fierro-lewis told the plant's changes (its true dynamic model)",
    "policy-dr": "an MLP policy trained off-line over randomized robots (PPO), no learning on-line",
}
COLOURS = (
    "**colours**: v, omega: commanded blue, measured orange, reference grey; wheels: left blue, right red, "
    "pale when measured"
)
LEARNING_COLOURS = "; weights: NN_f hidden green, NN_f output blue, NN_G hidden pink, NN_G output orange"


def controller_text(name: str) -> str:
    if name in CONTROLLERS:
        return CONTROLLERS[name]
    return "a variant of the paper's adaptive scheme" if name.startswith("adaptive") else ""


def about_text(record: RunRecord, description: str = "", ended: bool = False) -> str:
    """Markdown for the text panel (``ended``: with the run's figures and where to look)."""
    what = controller_text(record.controller)
    lines = [
        f"**{record.scenario}**" + (f": {description}" if description else ""),
        "",
        f"**controller** `{record.controller}`" + (f": {what}" if what else "") + f"; seed {record.seed}",
        "",
    ]
    if record.events:
        for ev in record.events:
            lines.append(
                f"**event at {float(ev['time']):g} s**: {ev.get('text') or ev.get('kind')}; the controller is not told"
            )
    elif record.split_s is not None:
        lines.append(f"**event at {record.split_s:g} s**; the controller is not told")
    else:
        lines.append("**no event**: the robot as the controller believes it")
    if record.pose_source != "truth":
        fixes = ", the fixes lime as they arrive" if record.pose_source == "fused" else ""
        lines += ["", f"**pose from {record.pose_source}**: the controller is given the robot's own estimate; the "
                  f"true path blue, the believed path teal{fixes}; the figures are the truth's"]  # fmt: skip
    if ended:
        lines += ["", *_where_to_look(record)]
    lines += ["", COLOURS + (LEARNING_COLOURS if "z" in record.ctrl else "") + "; events: dark-red diamonds"]
    return "\n".join(lines) + "\n"


def _where_to_look(record: RunRecord) -> list[str]:
    n = record.n
    w = min(int(round(record.warmup_s / record.T)), n)
    e = record.e_true[w:n]
    e = e[np.all(np.isfinite(e), axis=1)]
    m = metrics(record)  # the figures of metrics.json, computed once
    words, how = outcome_words(m), m["outcome"]
    out = [f"**{how}**{words[len(how) :]}"]  # the outcome metrics.json records, as the run's first line says it
    run = RunMetrics.from_json(m)
    est = run.estimate
    if est:  # what the robot believed: a belief that tracked while the truth was lost, said first
        out += ["", f"**{est['said']}**"] if est.get("said") else []
        out += [""]
        out.append(
            f"the estimate's error (believed - true): position RMS {1e3 * (est['rms_position_error_m'] or 0):.1f} mm, "
            f"max {1e3 * (est['max_position_error_m'] or 0):.1f} mm"
        )
    whole = run.figures("whole")
    if not len(e) or whole is None:
        return out
    e1, e2 = float(np.mean(e[:, 0])), float(np.mean(e[:, 1]))
    out += [
        "",
        f"after the {record.warmup_s:g} s warm-up: position RMS **{1e3 * whole[0]:.1f} mm**, "
        f"mean e1 {1e3 * e1:+.1f} mm, mean e2 {1e3 * e2:+.1f} mm",
        "",
    ]
    if abs(e1) > 0.01 and abs(e1) > 3 * abs(e2):
        side = "behind" if e1 > 0 else "ahead of"
        lag = f"- e1: the robot runs {side} its reference by {1e3 * abs(e1):.0f} mm on average, along the path"
        if record.controller.startswith("adaptive"):
            lag += "; the networks do not learn this lag away (the finding on the robot: docs/results-dynamics.md)"
        out.append(lag)
    before, after = run.figures("before"), run.figures("after")
    if record.split_s is not None and before is not None and after is not None:
        out.append(
            f"- the event at {record.split_s:g} s: position RMS {1e3 * before[0]:.1f} mm before, "
            f"{1e3 * after[0]:.1f} mm after"
        )
    if record.controller != "corradini":
        out.append(
            f"- next: the same seed without learning, `mlpfac run {record.scenario} --controller corradini "
            f"--seed {record.seed}`, then `mlpfac view` both folders"
        )
    return out
