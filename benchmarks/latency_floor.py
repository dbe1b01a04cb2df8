#!/usr/bin/env python3
"""The floor of one whole adaptive run, as a process: start Python, import numpy and MuJoCo, load
the robot, then per control step the bare physics (``mj_step`` x substeps) and one reference EKF
weight update (alpha = 171 weights, m = 3, numpy short form). Nothing of mlpfac is imported, so
the floor does not move when mlpfac gets faster or slower.

    python benchmarks/latency_floor.py models/scene.xml [--steps 2500] [--substeps 4] [--alpha 171]

prints the process's own compute time; time the whole process from outside to include the
interpreter's start and the imports (``benchmarks/bench_latency.py`` does). ``--compare`` times a
command against this process, interleaved, and prints both medians and the ratio command / floor:

    python benchmarks/latency_floor.py models/scene.xml --compare "mlpfac run eight-nominal --out /tmp/x" --repeats 3
"""

from __future__ import annotations

import argparse
import shlex
import statistics
import subprocess
import sys
import time


def floor(model: str, steps: int, substeps: int, alpha: int, m: int = 3) -> float:
    """Seconds of the floor's compute: load the model, then ``steps`` x (physics + EKF update)."""
    import mujoco
    import numpy as np

    t0 = time.perf_counter()
    mdl = mujoco.MjModel.from_xml_path(model)
    d = mujoco.MjData(mdl)
    ctrl = np.full(mdl.nu, 10.0)  # a constant command, within the actuators' ranges
    lim = mdl.actuator_ctrllimited.astype(bool)
    ctrl[lim] = np.clip(ctrl[lim], mdl.actuator_ctrlrange[lim, 0], mdl.actuator_ctrlrange[lim, 1])
    d.ctrl[:] = ctrl
    rng = np.random.default_rng(0)
    P = 0.1 * np.eye(alpha)
    B = np.empty_like(P)
    z = rng.normal(0.0, 0.3, alpha)
    H = rng.normal(0.0, 0.3, (m, alpha))
    Ht = np.ascontiguousarray(H.T)
    R = 1e-3 * np.eye(m)
    innov = rng.normal(0.0, 1e-3, m)
    for _ in range(steps):
        mujoco.mj_step(mdl, d, nstep=substeps)
        PHt = P @ Ht  # the short form: K = P H' S^-1, P <- P - K H P
        S = H @ PHt + R
        K = np.linalg.solve(S, PHt.T).T
        z += K @ innov
        np.matmul(K, PHt.T, out=B)
        np.subtract(P, B, out=P)
    return time.perf_counter() - t0


def wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"command failed (rc {r.returncode}): {shlex.join(cmd)}: {r.stderr.strip()[-300:]}")
    return dt


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("model")
    ap.add_argument("--steps", type=int, default=2500)
    ap.add_argument("--substeps", type=int, default=4)
    ap.add_argument("--alpha", type=int, default=171)
    ap.add_argument("--compare", help="a command line to time against the floor process")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child or not a.compare:
        print(f"compute {floor(a.model, a.steps, a.substeps, a.alpha):.3f} s")
        return 0
    me = [sys.executable, __file__, a.model, "--steps", str(a.steps), "--substeps", str(a.substeps)]
    me += ["--alpha", str(a.alpha), "--child"]
    cmd = shlex.split(a.compare)
    fl, cm = [], []
    for _ in range(a.repeats):
        fl.append(wall(me))
        cm.append(wall(cmd))
    f, c = statistics.median(fl), statistics.median(cm)
    print(f"floor process {f:.2f} s (min {min(fl):.2f}), command {c:.2f} s (min {min(cm):.2f}), ratio {c / f:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
