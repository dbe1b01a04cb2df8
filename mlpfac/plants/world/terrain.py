"""The world in the MuJoCo robot's compiled step: the ground's height under a point (the divergence
test and a reset measure the robot against it), the rough ground's smooth surface and the contact
tiles that carry the wheels and casters on it, the floor patches' friction switched under each
tyre, and the force of the ``force`` events applied to the robot's root body.

The rough ground is one smooth function (:func:`bumps_at`): value noise, a bi-smoothstep between
random heights on a coarse grid of nodes, normalised, scaled and flattened on a pad around the
robot's start (:mod:`mlpfac.plants.world.layout`). The heightfield MuJoCo is given (the chassis touches it,
the viewer draws it) is this function sampled (:func:`sample_bumps`); the wheels and casters touch
it through a contact tile each (:func:`place_tiles`): a plane on a mocap body, the surface's
tangent plane where the geom touches it, moved before every physics step. MuJoCo tests a sphere
against its heightfield's prisms one by one (GJK and EPA each): 2.5 times the whole step of a robot
on the flat floor; a sphere on a plane is one closed-form test, and the tile follows the smooth
surface itself, where the heightfield's triangles have kinks every grid cell.

What the step reads of the world is packed into one array (:func:`pack`, the layout below) and the
rough ground's nodes into another (``nodes``, empty without bumps); a run without a world or a
force packs nothing and its step does none of this (its bits are the ones it always had).
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel

# the packed world: counts, the step the force schedule is at (the one number that changes as the
# run steps), the rough ground's constants (1 when there is one, its nodes' origin and spacing, the
# nodes' lowest value and range, the scale to metres, the start pad's centre, radius and blend),
# then 9 numbers a ramp (x, y, cos, sin of its heading, up, top, down, height, width), 4 a patch
# (x, y, radius^2, mu), 2 a tyre (geom id, its friction off the patches), 3 a contact tile (the
# geom it carries, its mocap index, the geom's reach below its centre)
W_NRAMP, W_NPATCH, W_NTYRE, W_NTILE, W_STEP = range(5)
W_BUMPS, W_BX0, W_BY0, W_BS, W_FMIN, W_FRANGE, W_SCALE, W_PADX, W_PADY, W_PAD0, W_PADW = range(5, 16)
W_Z0 = 16  # the floor's height in the world (a Menagerie scene's may not be 0): the ground's heights are above it
W_HEAD, W_RAMP, W_PATCH, W_TYRE, W_TILE = 17, 9, 4, 2, 3
BUMPS = (W_BX0, W_BY0, W_BS, W_FMIN, W_FRANGE, W_SCALE, W_PADX, W_PADY, W_PAD0, W_PADW)


def pack(terrain=None, tyres=(), mus=(), tiles=(), floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The packed world of a :class:`~mlpfac.plants.world.layout.Terrain` (or None), the tyres' geom ids and
    friction off the patches, the contact tiles (geom, mocap index, reach) and the floor's height;
    and the rough ground's nodes ((0, 0) without bumps)."""
    ramps = () if terrain is None else terrain.raised  # a kerb: a ramp of vertical slopes (up = down = 0)
    patches = () if terrain is None else terrain.patches
    w = np.zeros(W_HEAD + W_RAMP * len(ramps) + W_PATCH * len(patches) + W_TYRE * len(tyres) + W_TILE * len(tiles))
    w[[W_NRAMP, W_NPATCH, W_NTYRE, W_NTILE, W_Z0]] = len(ramps), len(patches), len(tyres), len(tiles), floor
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
    for tile in tiles:
        w[o : o + W_TILE] = tile
        o += W_TILE
    nodes = np.zeros((0, 0))
    if terrain is not None and terrain.nodes is not None:
        nodes = np.ascontiguousarray(terrain.nodes, dtype=float)
        w[W_BUMPS] = 1.0
        w[list(BUMPS)] = terrain.surface
    return w, nodes


@kernel()
def offsets(w):
    """Where the ramps, the patches, the tyres and the tiles start in a packed world."""
    ramps = W_HEAD
    patches = ramps + W_RAMP * int(w[W_NRAMP])
    tyres = patches + W_PATCH * int(w[W_NPATCH])
    return ramps, patches, tyres, tyres + W_TYRE * int(w[W_NTYRE])


@kernel()
def _smooth(t, width):
    """The smoothstep 3 t^2 - 2 t^3 of t clamped to [0, 1], and its derivative / ``width``."""
    if t <= 0.0:
        return 0.0, 0.0
    if t >= 1.0:
        return 1.0, 0.0
    return t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t) / width


@kernel()
def bumps_at(w, nodes, x, y):
    """The rough ground's height at (x, y) and its slopes (dh/dx, dh/dy): the bi-smoothstep between
    the nodes, (f - fmin) / frange x scale, times the start pad's blend; 0 beyond the nodes' grid."""
    s = w[W_BS]
    u, v = (x - w[W_BX0]) / s, (y - w[W_BY0]) / s
    if not (0.0 <= u < nodes.shape[1] - 1 and 0.0 <= v < nodes.shape[0] - 1):
        return 0.0, 0.0, 0.0
    j, i = int(u), int(v)
    su, dsu = _smooth(u - j, s)
    sv, dsv = _smooth(v - i, s)
    a, b, c, d = nodes[i, j], nodes[i, j + 1], nodes[i + 1, j], nodes[i + 1, j + 1]
    top, bottom = a + (b - a) * su, c + (d - c) * su
    f = top + (bottom - top) * sv
    fx = ((b - a) + ((d - c) - (b - a)) * sv) * dsu
    fy = (bottom - top) * dsv
    k = w[W_SCALE] / w[W_FRANGE]
    g, gx, gy = (f - w[W_FMIN]) * k, fx * k, fy * k
    px, py = x - w[W_PADX], y - w[W_PADY]
    r2, out = px * px + py * py, w[W_PAD0] + w[W_PADW]
    if r2 >= out * out:  # beyond the start pad
        return g, gx, gy
    r = math.sqrt(r2)
    blend, dblend = _smooth((r - w[W_PAD0]) / w[W_PADW], w[W_PADW])
    if dblend != 0.0:
        gx, gy = gx * blend + g * dblend * px / r, gy * blend + g * dblend * py / r
    else:
        gx, gy = gx * blend, gy * blend
    return g * blend, gx, gy


@kernel("void(f8[::1], f8[:, ::1], f8, f8, f8, f8, f8[:, ::1])")
def sample_bumps(w, nodes, x0, y0, dx, dy, out):
    """The rough ground's heights at x0 + j dx, y0 + i dy into ``out`` (rows i, columns j)."""
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = bumps_at(w, nodes, x0 + j * dx, y0 + i * dy)[0]


@kernel()
def ground_at(w, nodes, x, y):
    """The ground's height at (x, y) above the floor (m): the rough ground and the ramps (up, top,
    down across their width; a kerb's top all of it), the highest of them."""
    h = 0.0
    if w[W_BUMPS] != 0.0:
        h = bumps_at(w, nodes, x, y)[0]
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
def ground_height(w, nodes, x, y):
    """:func:`ground_at`, for Python."""
    return ground_at(w, nodes, x, y)


@kernel()
def place_tiles(w, nodes, geom_xpos, mocap_pos, mocap_quat):
    """Each contact tile on the rough ground's tangent plane where its geom touches it
    (``geom_xpos``, flat: the geom as the last kinematics left it): the point its reach below the
    geom's centre along the tile's last normal (where the surface's normal points at the centre, a
    physics step ago; ``mocap_pos``, ``mocap_quat``: the data's, flat)."""
    o = offsets(w)[3]
    for _ in range(int(w[W_NTILE])):
        g, m, reach = int(w[o]), int(w[o + 1]), w[o + 2]
        qw, qx, qy = mocap_quat[4 * m], mocap_quat[4 * m + 1], mocap_quat[4 * m + 2]
        x = geom_xpos[3 * g] - reach * 2.0 * qw * qy  # the last normal: R(q) z = (2 w y, -2 w x, ...) (q_z = 0)
        y = geom_xpos[3 * g + 1] + reach * 2.0 * qw * qx
        h, hx, hy = bumps_at(w, nodes, x, y)
        n = 1.0 / math.sqrt(1.0 + hx * hx + hy * hy)
        nx, ny, nz = -hx * n, -hy * n, n
        mocap_pos[3 * m], mocap_pos[3 * m + 1], mocap_pos[3 * m + 2] = x, y, w[W_Z0] + h
        q = 1.0 / math.sqrt(2.0 * (1.0 + nz))  # the turn of z onto the normal: (1 + nz, z x n) / |.|
        mocap_quat[4 * m], mocap_quat[4 * m + 1] = (1.0 + nz) * q, -ny * q
        mocap_quat[4 * m + 2], mocap_quat[4 * m + 3] = nx * q, 0.0
        o += W_TILE


@kernel()
def patches(w, friction, geom_xpos):
    """Each tyre's sliding friction (``friction``: the model's geom_friction, flat) set to the patch's
    under its centre (``geom_xpos``, flat), or its own off the patches (the first patch listed wins)."""
    _, o, t, _ = offsets(w)
    npatch = int(w[W_NPATCH])
    for k in range(int(w[W_NTYRE])):
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
