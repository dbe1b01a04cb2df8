"""The world in the MuJoCo robot's compiled step: the ground's height under a point (the divergence
test and a reset measure the robot against it), the floor patches' friction switched under each
tyre, and the force of the ``force`` events applied to the robot's root body, every control step.

What the step reads of the world is packed into one array (:func:`pack`, the layout below) and
the rough ground's heights into another (``ground`` (rows, columns), empty without bumps); a run
without a world or a force packs nothing and its step does none of this (its bits are the ones it
always had).
"""

from __future__ import annotations

import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel

# the packed world: counts, the heightfield's origin and cells, the step the force schedule is at
# (the one number that changes as the run steps), then 9 numbers a ramp (x, y, cos, sin of its
# heading, up, top, down, height, width), 4 a patch (x, y, radius^2, mu), 2 a tyre (geom id, its
# friction off the patches)
W_NRAMP, W_NPATCH, W_NTYRE, W_X0, W_Y0, W_DX, W_DY, W_STEP = range(8)
W_HEAD, W_RAMP, W_PATCH, W_TYRE = 8, 9, 4, 2


def pack(terrain=None, tyres=(), mus=()) -> tuple[np.ndarray, np.ndarray]:
    """The packed world of a :class:`~mlpfac.plants.world.Terrain` (or None) and the tyres' geom ids
    and friction off the patches, and its heights (rows, columns) ((0, 0) without bumps)."""
    ramps = () if terrain is None else terrain.ramps
    patches = () if terrain is None else terrain.patches
    w = np.zeros(W_HEAD + W_RAMP * len(ramps) + W_PATCH * len(patches) + W_TYRE * len(tyres))
    w[[W_NRAMP, W_NPATCH, W_NTYRE]] = len(ramps), len(patches), len(tyres)
    o = W_HEAD
    for r in ramps:
        w[o : o + W_RAMP] = (r.x, r.y, r.c, r.s, r.up, r.top, r.down, r.height, r.width)
        o += W_RAMP
    for p in patches:
        w[o : o + W_PATCH] = (p.x, p.y, p.radius * p.radius, p.mu)
        o += W_PATCH
    for g, mu in zip(tyres, mus, strict=True):
        w[o : o + W_TYRE] = (g, mu)
        o += W_TYRE
    grid = np.zeros((0, 0))
    if terrain is not None and terrain.grid is not None:
        grid = np.ascontiguousarray(terrain.grid, dtype=float)
        w[[W_X0, W_Y0, W_DX, W_DY]] = (terrain.arena[0], terrain.arena[1], *terrain.cell)
    return w, grid


@kernel()
def ground_at(w, grid, x, y):
    """The ground's height at (x, y) (m): the rough ground (bilinear between its points; 0 beyond
    the arena) and the ramps (up, top, down across their width), the highest of them."""
    h = 0.0
    nr, nc = grid.shape[0], grid.shape[1]
    if nr > 1:
        u, v = (x - w[W_X0]) / w[W_DX], (y - w[W_Y0]) / w[W_DY]
        if 0.0 <= u <= nc - 1 and 0.0 <= v <= nr - 1:
            j, i = min(int(u), nc - 2), min(int(v), nr - 2)
            tu, tv = u - j, v - i
            a = grid[i, j] + (grid[i, j + 1] - grid[i, j]) * tu
            b = grid[i + 1, j] + (grid[i + 1, j + 1] - grid[i + 1, j]) * tu
            h = a + (b - a) * tv
    o = W_HEAD
    for _ in range(int(w[W_NRAMP])):
        dx, dy = x - w[o], y - w[o + 1]
        along, across = dx * w[o + 2] + dy * w[o + 3], -dx * w[o + 3] + dy * w[o + 2]
        up, top, down, height = w[o + 4], w[o + 5], w[o + 6], w[o + 7]
        if 0.0 <= along <= up + top + down and abs(across) <= 0.5 * w[o + 8]:
            if along < up:
                z = height * along / up
            elif along <= up + top:
                z = height
            else:
                z = height * (up + top + down - along) / down
            h = max(h, z)
        o += W_RAMP
    return h


@kernel("f8(f8[::1], f8[:, ::1], f8, f8)")
def ground_height(w, grid, x, y):
    """:func:`ground_at`, for Python."""
    return ground_at(w, grid, x, y)


@kernel()
def patches(w, friction, geom_xpos):
    """Each tyre's sliding friction (``friction``: the model's geom_friction, flat) set to the patch's
    under its centre (``geom_xpos``, flat), or its own off the patches (the first patch listed wins)."""
    npatch, ntyre = int(w[W_NPATCH]), int(w[W_NTYRE])
    o = W_HEAD + W_RAMP * int(w[W_NRAMP])
    t = o + W_PATCH * npatch
    for k in range(ntyre):
        g, mu = int(w[t + W_TYRE * k]), w[t + W_TYRE * k + 1]
        x, y = geom_xpos[3 * g], geom_xpos[3 * g + 1]
        for p in range(npatch):
            q = o + W_PATCH * p
            if (x - w[q]) * (x - w[q]) + (y - w[q + 1]) * (y - w[q + 1]) <= w[q + 2]:
                mu = w[q + 3]
                break
        friction[3 * g] = mu


@kernel()
def push(w, schedule, xfrc, root, theta, out):
    """The force of this control step (the schedule's row at the step the world is at, which moves
    on by one) on the root body, at its centre of mass (``xfrc``: the data's xfrc_applied, flat):
    the world's (fx, fy) and the robot's turned by its heading ``theta``, and torque_z; written to
    ``out`` (3,) as applied, in the world's axes."""
    k = int(w[W_STEP])
    w[W_STEP] = k + 1
    fx, fy, tz = 0.0, 0.0, 0.0
    if k < schedule.shape[0]:
        c, s = cos(theta), sin(theta)
        fx = schedule[k, 0] + c * schedule[k, 2] - s * schedule[k, 3]
        fy = schedule[k, 1] + s * schedule[k, 2] + c * schedule[k, 3]
        tz = schedule[k, 4]
    xfrc[6 * root], xfrc[6 * root + 1], xfrc[6 * root + 5] = fx, fy, tz
    out[0], out[1], out[2] = fx, fy, tz
