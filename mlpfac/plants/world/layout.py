"""The world around the robot on a run: a scenario's ``[world]`` (:mod:`mlpfac.plants.world.table`,
the table as plain, validated data) laid out along the run's reference and drawn for its seed.
:func:`resolve` turns it into the :class:`Terrain` a run drives on, once, from the reference over
the whole run and the run's seed: where each ramp and kerb lies (``at``, a share of the path's
length, or its centre at (``x``, ``y``)), the heights of the rough ground, the arena. Every plant
of a run, and the probes a run builds, is given that one terrain, so they all build the same world (:mod:`mlpfac.plants.mujoco.world` builds it into the robot's scene). What is
drawn is recorded by its digest (:attr:`Terrain.digest`, the scenario's ``[drawn]``).

The rough ground is value noise, arithmetic only (the same bits on every machine): uniform random
heights in [0, height) on a lattice of nodes every half wavelength, fixed in the world and drawn
from streams of their own (the run's seed, ``BUMPS_STREAM``, the node's row: the same ground under
a shorter run), a bi-smoothstep between them, flattened to 0 within ``START_PAD`` of the robot's
start (blending in over half a wavelength), where the robot rests as it settled on the flat floor
(:func:`mlpfac.plants.world.terrain.bumps_at`, one function for the heightfield sampled eight points a
wavelength, the contact tiles and the divergence test).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.world.table import Bumps, Kerb, Patch, Ramp, World

RAMP_WIDTH = 1.2  # m across the path, where a ramp does not say
ARENA_MARGIN = 1.0  # m: the arena is the reference's bounding box and this much around it (the viewer's floor)
START_PAD = 0.5  # m: the rough ground is flat within this of the robot's start
GRID_POINTS_MAX = 4_000_000  # points of a heightfield, at most
POINTS_PER_WAVE = 8  # heightfield points a wavelength
BUMPS_STREAM = 0x62756D70  # tags the rough ground's streams apart from every other stream of a run
NODE0 = 2**31  # a node's row and column counted from here (the streams take whole numbers >= 0)
PROBE = 8  # the digest of a draw: the nodes within this many of the world's origin


@dataclass(frozen=True)
class PlacedRamp:
    """A ramp or a kerb where it lies: its foot's middle (x, y), the heading up it (its cosine and
    sine), the lengths of its three parts along it (a kerb's slopes none: its top all of it), its
    height and width (m)."""

    x: float
    y: float
    c: float
    s: float
    up: float
    top: float
    down: float
    height: float
    width: float
    placed: str = "at"  # the key that placed it: "at" (a share of the path) or "x" (its centre)

    def corners(self) -> np.ndarray:
        """Its prism's 8 corners (8, 3), above the floor: its foot, the top's two edges and its end
        (along it), each at its two sides (across it), at the floor and at their heights."""
        profile = [
            (0.0, 0.0),
            (self.up, self.height),
            (self.up + self.top, self.height),
            (self.up + self.top + self.down, 0.0),
        ]
        out = []
        for along, z in profile:
            for across in (-0.5 * self.width, 0.5 * self.width):
                out.append([self.x + along * self.c - across * self.s, self.y + along * self.s + across * self.c, z])
        return np.array(out)

    @property
    def kerb(self) -> bool:
        """A kerb: vertical steps (no slopes), its top all of its length."""
        return self.up == 0.0

    def near(self, x: float, y: float) -> float:
        """How far (x, y) is from its footprint (m; 0 on it)."""
        u = (x - self.x) * self.c + (y - self.y) * self.s
        w = -(x - self.x) * self.s + (y - self.y) * self.c
        du = max(0.0, -u, u - (self.up + self.top + self.down))
        dw = max(0.0, abs(w) - 0.5 * self.width)
        return math.sqrt(du * du + dw * dw)


@dataclass(frozen=True, eq=False)
class Terrain:
    """The ground a run drives on (:func:`resolve`): the arena (x0, y0, x1, y1), where the robot
    starts, its ramps and kerbs where they lie, the patches, and the rough ground: its random ``nodes`` (rows along y, columns along x)
    and the constants of its surface (:data:`mlpfac.plants.world.terrain.BUMPS`), its heights sampled on
    the arena (``grid`` (rows, columns): row i at y = y0 + i dy, column j at x = x0 + j dx, the
    heightfield), the digest of what was drawn; None without bumps."""

    arena: tuple[float, float, float, float]
    start: tuple[float, float]  # where the robot starts (x, y): on the flat floor
    ramps: tuple[PlacedRamp, ...] = ()
    patches: tuple[Patch, ...] = ()
    bumps: Bumps | None = None
    nodes: np.ndarray | None = None
    surface: tuple[float, ...] = ()
    grid: np.ndarray | None = None
    cell: tuple[float, float] = (0.0, 0.0)  # (dx, dy) of the grid
    digest: str = ""  # sha256 of the draw (draw_bumps; "" without bumps)
    kerbs: tuple[PlacedRamp, ...] = ()

    @property
    def raised(self) -> tuple[PlacedRamp, ...]:
        """Its ramps, then its kerbs: what stands on the floor (each a convex mesh of the scene)."""
        return self.ramps + self.kerbs

    def packed(self) -> tuple[np.ndarray, np.ndarray]:
        """Its packed form (:func:`mlpfac.plants.world.terrain.pack`): the world array and the nodes."""
        from mlpfac.plants.world.terrain import pack

        return pack(self)

    def height(self, x: float, y: float) -> float:
        """The ground's height at (x, y) (m): the rough ground, the ramps and the kerbs, the highest of them."""
        from mlpfac.plants.world.terrain import ground_height

        return float(ground_height(*self.packed(), float(x), float(y)))

    def as_dict(self) -> dict:
        """What a recording draws of it (plain numbers and arrays): :mod:`mlpfac.log.terrain`."""
        return {
            "arena": list(self.arena),
            "ramps": [r.corners() for r in self.ramps],
            "kerbs": [r.corners() for r in self.kerbs],
            "patches": [{"x": p.x, "y": p.y, "radius": p.radius, "mu": p.mu} for p in self.patches],
            "grid": None if self.grid is None else self.grid.astype(np.float32),
            "cell": list(self.cell),
            "packed": self.packed(),  # the ground's heights, as the plant measures them
        }


def resolve(world: World, ref: np.ndarray, start: np.ndarray, seed: int, where: str) -> Terrain | None:
    """The terrain of ``world`` for a run: ``ref`` (N + 1, 5) the reference over the whole run,
    ``start`` the robot's start (x, y), ``seed`` the run's. None for an empty world. A patch, a ramp
    or a kerb placed outside the arena is a ConfigError naming it (``where``: ``[world]``; one under
    the robot's start is the plant's, which knows how far the robot reaches)."""
    if not world:
        return None
    xy = ref[:, :2]
    lo, hi = xy.min(axis=0) - ARENA_MARGIN, xy.max(axis=0) + ARENA_MARGIN
    arena = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    for key in ("patches", "ramps", "kerbs"):
        for i, p in enumerate(getattr(world, key)):
            if p.x is not None and not (arena[0] <= p.x <= arena[2] and arena[1] <= p.y <= arena[3]):
                raise ConfigError(
                    f"{where} {key} #{i + 1}",
                    f"({p.x:g}, {p.y:g}) lies outside the arena x {arena[0]:.3g} .. {arena[2]:.3g}, y {arena[1]:.3g} "
                    f".. {arena[3]:.3g} m (the reference's bounding box and {ARENA_MARGIN:g} m around it)",
                )
    ramps, kerbs = tuple(_place(r, ref) for r in world.ramps), tuple(_place(k, ref) for k in world.kerbs)
    at = (float(start[0]), float(start[1]))
    if world.bumps is None:
        return Terrain(arena, at, ramps, world.patches, kerbs=kerbs)
    nodes, surface, grid, cell, digest = draw_bumps(world.bumps, arena, start, seed, f"{where} bumps")
    return Terrain(arena, at, ramps, world.patches, world.bumps, nodes, surface, grid, cell, digest, kerbs)


def _place(feature: Ramp | Kerb, ref: np.ndarray) -> PlacedRamp:
    """Where a ramp or a kerb lies: at (x, y), its centre, uphill towards its heading; or on the
    reference ``ref`` (N + 1, 5), its foot where the path has gone ``at`` of its length (linear
    between samples), heading along the path there. A ramp's slopes are each a third of its length;
    a kerb's none (vertical steps)."""
    from mlpfac.elementary import cos, sin

    if isinstance(feature, Kerb):
        up, top, down = 0.0, feature.length, 0.0
    else:
        third = feature.length / 3.0
        up, top, down = third, third, feature.length - 2.0 * third
    width = RAMP_WIDTH if feature.width is None else feature.width
    if feature.at is None:
        th = (feature.heading_deg or 0.0) * (math.pi / 180.0)
        c, s = cos(th), sin(th)
        half = 0.5 * feature.length
        return PlacedRamp(feature.x - half * c, feature.y - half * s, c, s, up, top, down, feature.height, width, "x")
    d = np.diff(ref[:, :2], axis=0)
    ds = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    s = np.concatenate([[0.0], np.cumsum(ds)])
    goal = feature.at * float(s[-1])
    j = min(max(int(np.searchsorted(s, goal)), 1), len(s) - 1)
    t = 0.0 if ds[j - 1] == 0 else (goal - float(s[j - 1])) / float(ds[j - 1])
    x = float(ref[j - 1, 0]) + t * float(d[j - 1, 0])
    y = float(ref[j - 1, 1]) + t * float(d[j - 1, 1])
    th = float(ref[j - 1, 2]) + t * (float(ref[j, 2]) - float(ref[j - 1, 2]))
    return PlacedRamp(x, y, cos(th), sin(th), up, top, down, feature.height, width)


def node_heights(seed: int, rows: range, cols: range) -> np.ndarray:
    """The rough ground's random node heights, uniform on [0, 1), at the nodes (i, j) of ``rows`` x
    ``cols`` (node (i, j) at (j, i) x half a wavelength from the world's origin): each row its own
    stream (the seed, ``BUMPS_STREAM``, the row), advanced to the row's first column, so that a node's
    height is the same whatever the arena (a shorter run, a slower robot: the same ground)."""
    out = np.empty((len(rows), len(cols)))
    for k, i in enumerate(rows):
        bits = np.random.PCG64(np.random.SeedSequence([BUMPS_STREAM, int(seed), i + NODE0]))
        bits.advance(cols.start + NODE0)
        out[k] = np.random.Generator(bits).random(len(cols))
    return out


def draw_bumps(bumps: Bumps, arena: tuple[float, float, float, float], start: np.ndarray, seed: int, where: str):
    """The rough ground of ``bumps`` over ``arena`` for ``seed`` (the module's docstring): its nodes
    (:func:`node_heights`, every node the arena's surface needs), the constants of its surface
    (:data:`mlpfac.plants.world.terrain.BUMPS`), its heights sampled on a grid of the arena (the
    heightfield), the grid's (dx, dy) and the digest of the draw (of the nodes about the world's
    origin, and the wavelength and height: the arena's nodes are the same)."""
    from mlpfac.plants.world.terrain import BUMPS, W_HEAD, sample_bumps

    x0, y0, x1, y1 = arena
    lam = bumps.wavelength
    ncol = int(math.ceil((x1 - x0) * POINTS_PER_WAVE / lam)) + 1
    nrow = int(math.ceil((y1 - y0) * POINTS_PER_WAVE / lam)) + 1
    if nrow * ncol > GRID_POINTS_MAX:
        raise ConfigError(
            f"{where} wavelength",
            f"{lam:g} m over an arena of {x1 - x0:.3g} x {y1 - y0:.3g} m takes a heightfield of {nrow} x {ncol} points; "
            f"the limit is {GRID_POINTS_MAX:.0e}: lengthen the wavelength",
        )
    dx, dy = (x1 - x0) / (ncol - 1), (y1 - y0) / (nrow - 1)
    node = 0.5 * lam
    i0, j0 = int(math.floor(y0 / node)), int(math.floor(x0 / node))
    rows, cols = range(i0, int(math.ceil(y1 / node)) + 2), range(j0, int(math.ceil(x1 / node)) + 2)
    nodes = node_heights(seed, rows, cols)
    surface = (j0 * node, i0 * node, node, 0.0, 1.0, bumps.height, float(start[0]), float(start[1]), START_PAD, node)
    w = np.zeros(W_HEAD)
    w[list(BUMPS)] = surface
    grid = np.empty((nrow, ncol))
    sample_bumps(w, nodes, x0, y0, dx, dy, grid)
    probe = node_heights(seed, range(-PROBE, PROBE), range(-PROBE, PROBE))
    digest = hashlib.sha256(probe.tobytes() + np.array([lam, bumps.height]).tobytes()).hexdigest()
    return nodes, surface, grid, (dx, dy), digest
