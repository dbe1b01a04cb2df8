"""Figure 1 of the paper redrawn from a run record: (a)-(c) errors, (d) weights, (e)-(f) paths,
(g) mean diag(P_k), (h) e2 of the non-adaptive law on the same scenario and seed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mlpfac.record import RunRecord


def figure1(rec: RunRecord, baseline: RunRecord | None, path: Path) -> None:
    """Write the eight panels of Figure 1 for ``rec`` (and ``baseline`` for panel h) to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = rec.n
    t = rec.t[:n]
    fig, ax = plt.subplots(4, 2, figsize=(11, 12), constrained_layout=True)
    ax = ax.ravel()
    title = f"{rec.scenario} / {rec.controller} / seed {rec.seed} — {rec.status}"
    fig.suptitle(title + (f" ({rec.reason})" if rec.reason else ""))
    for i, (name, unit) in enumerate([("e1", "m"), ("e2", "m"), ("e3", "rad")]):
        ax[i].plot(t, rec.e_true[:n, i], lw=0.8)
        ax[i].set(title=f"({'abc'[i]}) {name}", xlabel="t [s]", ylabel=f"{name} [{unit}]")
    z = rec.ctrl.get("z")
    if z is not None:
        labels = rec.labels.get("z", [])
        picks = np.linspace(0, z.shape[1] - 1, 4).astype(int)
        for j in picks:
            ax[3].plot(t, z[:n, j], lw=0.8, label=labels[j] if j < len(labels) else f"z{j}")
        ax[3].legend(fontsize=7)
        ax[3].set(title="(d) some weights", xlabel="t [s]")
    else:
        ax[3].plot(t, rec.u[:n, 0], lw=0.8, label="v [m/s]")
        ax[3].plot(t, rec.u[:n, 1], lw=0.8, label="omega [rad/s]")
        ax[3].legend(fontsize=7)
        ax[3].set(title="(d) commands (no weights: non-adaptive)", xlabel="t [s]")
    for i, (lo, hi, tag) in enumerate(
        [(0, n, "(e) reference (—) and actual (o) paths"), (0, min(n, int(round(3.0 / rec.T))), "(f) initial phase")]
    ):
        a = ax[4 + i]
        a.plot(rec.ref[lo:hi, 0], rec.ref[lo:hi, 1], "k-", lw=1.0)
        step = max(1, (hi - lo) // 300)
        a.plot(rec.pose[lo:hi:step, 0], rec.pose[lo:hi:step, 1], "o", ms=2, mfc="none")
        a.set(title=tag, xlabel="x [m]", ylabel="y [m]", aspect="equal")
    P = rec.ctrl.get("mean_diag_P")
    if P is not None:
        ax[6].semilogy(t, P[:n], lw=0.8)
        ax[6].set(title="(g) mean of diag(P_k)", xlabel="t [s]")
    else:
        ax[6].set(title="(g) mean of diag(P_k): not an adaptive run")
    if baseline is not None:
        nb = baseline.n
        ax[7].plot(baseline.t[:nb], baseline.e_true[:nb, 1], lw=0.8)
        ax[7].set(title=f"(h) e2, {baseline.controller} law ({baseline.status})", xlabel="t [s]", ylabel="e2 [m]")
    else:
        ax[7].set(title="(h) no baseline run")
    for ev in rec.events:
        for a in (ax[0], ax[1], ax[2], ax[3], ax[6], ax[7]):
            a.axvline(ev["time"], color="r", lw=0.6, ls="--")
    fig.savefig(path, dpi=90)
    plt.close(fig)
