"""The world around the robot, a scenario's ``[world]`` table: ramps and kerbs (slabs with vertical
steps), across the path or placed at (x, y), rough ground (a heightfield drawn per seed) and floor
patches of their own friction, present from the start.

:class:`World` is the table as plain, validated data (each key typed and ranged when it is made,
as an event's are: :func:`mlpfac.plants.events.param`). :func:`resolve` turns it into the
:class:`Terrain` a run drives on, once, from the reference over the whole run and the run's seed:
where each ramp and kerb lies (``at``, a share of the path's length, or its centre at (``x``,
``y``)), the heights of the rough ground, the arena. Every plant of a run, and the probes a run builds, is given that one terrain, so they all
build the same world (:mod:`mlpfac.plants.mujoco_world` builds it into the robot's scene). What is
drawn is recorded by its digest (:attr:`Terrain.digest`, the scenario's ``[drawn]``).

The rough ground is value noise, arithmetic only (the same bits on every machine): uniform random
heights in [0, height) on a lattice of nodes every half wavelength, fixed in the world and drawn
from streams of their own (the run's seed, ``BUMPS_STREAM``, the node's row: the same ground under
a shorter run), a bi-smoothstep between them, flattened to 0 within ``START_PAD`` of the robot's
start (blending in over half a wavelength), where the robot rests as it settled on the flat floor
(:func:`mlpfac.plants.terrain.bumps_at`, one function for the heightfield sampled eight points a
wavelength, the contact tiles and the divergence test).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import MU_MAX, MU_MIN, check_params, param
from mlpfac.tables import build, check_keys

RAMP_HEIGHT_MAX = 0.5  # m: a ramp up to half a metre high (a loading ramp), a kerb too
# m: a ramp's or a kerb's height, at least: lower, it is within the give of MuJoCo's soft contacts
# (a tyre sinks about 0.1 mm into the floor under the robot's weight) and its mesh is too flat for
# MuJoCo's convex hull (qhull: coplanar points, or pages of warnings)
HEIGHT_MIN = 1e-3
SIZE_MIN = 1e-3  # m: a ramp's or a kerb's length and width, at least
LENGTH_MAX = 50.0  # m: a ramp's length and width, a patch's radius, at most
FEATURES_MAX = 100  # ramps, kerbs and patches each, at most: each is a geom of the scene, a mesh in the recording, and looked up every step
BUMPS_HEIGHT_MAX = 0.2  # m of rough ground, top to bottom, at most
WAVELENGTH_MIN, WAVELENGTH_MAX = 0.01, 10.0  # m between crests of the rough ground
RAMP_WIDTH = 1.2  # m across the path, where a ramp does not say
ARENA_MARGIN = 1.0  # m: the arena is the reference's bounding box and this much around it (the viewer's floor)
START_PAD = 0.5  # m: the rough ground is flat within this of the robot's start
GRID_POINTS_MAX = 4_000_000  # points of a heightfield, at most
OVER_MAX = 1e5  # s of the reference a world is laid out along, at most
POINTS_PER_WAVE = 8  # heightfield points a wavelength
BUMPS_STREAM = 0x62756D70  # tags the rough ground's streams apart from every other stream of a run
NODE0 = 2**31  # a node's row and column counted from here (the streams take whole numbers >= 0)
PROBE = 8  # the digest of a draw: the nodes within this many of the world's origin
# The largest curvature of the bi-smoothstep surface of span h over nodes s apart: 6 h / s^2 along an
# axis and (3 / 2)^2 h / s^2 across, so at most 8.25 h / s^2; with s = wavelength / 2, 33 h / wavelength^2.
CURVATURE = 33.0


SHARE = {"required": False, "minimum": 0.0, "maximum": 1.0}  # a share of the path's length
PLACE = {"required": False, "minimum": -1e6, "maximum": 1e6}  # m, a place in the world
SIZE = {"minimum": SIZE_MIN, "maximum": LENGTH_MAX}  # m, a feature's length or width
TURN = {"required": False, "minimum": -360.0, "maximum": 360.0}  # deg, a heading
RISE = {"minimum": HEIGHT_MIN, "maximum": RAMP_HEIGHT_MAX}  # m, a ramp's or a kerb's height


@dataclass(frozen=True, kw_only=True)
class Placed:
    """Where a ramp or a kerb lies: across the path where the reference has gone ``at`` of its length
    over the run (heading along it there), or at (``x``, ``y``), its centre, heading ``heading_deg``."""

    at: float | None = param(float, **SHARE)  # where it begins: a share of the path's length over the run
    x: float | None = param(float, **PLACE)  # m: or its centre in the world (inside the arena)
    y: float | None = param(float, **PLACE)  # m
    heading_deg: float | None = param(float, **TURN)  # at (x, y): the way across it, from x, anticlockwise (none: 0)

    def __post_init__(self) -> None:
        check_params(self)
        here = [k for k in ("x", "y", "heading_deg") if getattr(self, k) is not None]
        if self.at is not None and here:
            raise ConfigError(here[0], "not with 'at': a feature lies at a share of the path or at (x, y), not both")
        if self.at is None and (self.x is None or self.y is None):
            raise ConfigError(
                "y" if self.x is not None else "x" if self.y is not None else "at",
                "give 'at' (a share of the path's length) or 'x' and 'y' (its centre in the world)",
            )
        if self.at is not None and not 0.0 < self.at < 1.0:
            raise ConfigError("at", f"a share of the path's length between 0 and 1 (not either), got {self.at!r}")


@dataclass(frozen=True, kw_only=True)
class Ramp(Placed):
    """A ramp: up, a flat top, down, each a third of ``length``, placed (:class:`Placed`) uphill."""

    height: float = param(float, **RISE)  # m, of its flat top
    length: float = param(float, **SIZE)  # m along it: up, top and down
    width: float | None = param(float, required=False, **SIZE)  # m across it (none: 1.2 m)

    @property
    def slope(self) -> float:
        """The tangent of its slopes' angle from the floor."""
        return 3.0 * self.height / self.length


@dataclass(frozen=True, kw_only=True)
class Kerb(Placed):
    """A kerb: a slab with vertical edges, a step up of ``height`` where the path meets it and a step
    down ``length`` further on, where it leaves it; placed (:class:`Placed`) step up first."""

    height: float = param(float, **RISE)  # m of each step; within the robot's wheels' reach
    length: float = param(float, **SIZE)  # m along it, from the step up to the step down
    width: float | None = param(float, required=False, **SIZE)  # m across it (none: 1.2 m)


@dataclass(frozen=True, kw_only=True)
class Bumps:
    """Rough ground over the whole arena: a heightfield drawn per seed (the module's docstring)."""

    height: float = param(float, positive=True, maximum=BUMPS_HEIGHT_MAX)  # m: heights drawn in [0, height)
    wavelength: float = param(float, minimum=WAVELENGTH_MIN, maximum=WAVELENGTH_MAX)  # m between crests

    def __post_init__(self) -> None:
        check_params(self)

    @property
    def curvature(self) -> float:
        """The largest curvature of its surface (1/m): a tyre of a larger radius than its inverse
        cannot touch the bottom of its troughs."""
        return CURVATURE * self.height / (self.wavelength * self.wavelength)


@dataclass(frozen=True, kw_only=True)
class Patch:
    """A floor patch of its own friction, flush with the floor (a wet patch the path crosses): the
    tyre touching the floor inside it slides on ``mu``."""

    x: float = param(float, minimum=-1e6, maximum=1e6)  # m, its centre in the world
    y: float = param(float, minimum=-1e6, maximum=1e6)  # m; inside the arena (the path's bounding box and 1 m)
    radius: float = param(float, positive=True, maximum=LENGTH_MAX)  # m
    mu: float = param(float, minimum=MU_MIN, maximum=MU_MAX)  # the tyre's sliding friction on it

    def __post_init__(self) -> None:
        check_params(self)


@dataclass(frozen=True)
class World:
    """A scenario's ``[world]`` table: ``ramps``, ``kerbs``, ``bumps``, ``patches``, and ``over``: the
    seconds of the reference it is laid out along (its arena, where its ramps and kerbs lie), the
    run's duration where it says none; ``--duration`` keeps the file's (written into config.toml),
    so that a shorter run drives into the same world."""

    ramps: tuple[Ramp, ...] = ()
    kerbs: tuple[Kerb, ...] = ()
    bumps: Bumps | None = None
    patches: tuple[Patch, ...] = ()
    over: float | None = None  # s of the reference it is laid out along (the arena, the ramps' `at`); none: the run's

    def __bool__(self) -> bool:
        return bool(self.ramps or self.kerbs or self.bumps or self.patches)


KEYS = {"ramps": Ramp, "kerbs": Kerb, "bumps": Bumps, "patches": Patch}


def parse_world(table, where: str) -> World:
    """The ``[world]`` table (``where`` names it in errors) as a :class:`World`, every key checked."""
    if not isinstance(table, dict):
        raise ConfigError(where, f"expected a table ([world]), got {table!r}")
    check_keys(table, {*KEYS, "over"}, where)
    out: dict = {}
    if "over" in table:
        over = table["over"]
        if isinstance(over, bool) or not isinstance(over, int | float) or not 0 < over <= OVER_MAX:
            raise ConfigError(
                f"{where} over", f"expected seconds of the reference, > 0 and <= {OVER_MAX:g}, got {over!r}"
            )
        out["over"] = float(over)
    for key, cls in KEYS.items():
        if key not in table:
            continue
        value = table[key]
        if key == "bumps":
            if not isinstance(value, dict):
                raise ConfigError(f"{where} bumps", f"expected a table {{height, wavelength}}, got {value!r}")
            out[key] = build(cls, value, f"{where} bumps")
            continue
        if not isinstance(value, list) or not all(isinstance(x, dict) for x in value):
            raise ConfigError(f"{where} {key}", f"expected a list of tables ({key} = [{{...}}, ...]), got {value!r}")
        if len(value) > FEATURES_MAX:
            raise ConfigError(
                f"{where} {key}",
                f"{len(value)} of them; the limit is {FEATURES_MAX} (each is a geom of the scene, a mesh of the "
                "recording, and looked up every step)",
            )
        out[key] = tuple(build(cls, x, f"{where} {key} #{i + 1}") for i, x in enumerate(value))
    return World(**out)


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
    and the constants of its surface (:data:`mlpfac.plants.terrain.BUMPS`), its heights sampled on
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
        """Its packed form (:func:`mlpfac.plants.terrain.pack`): the world array and the nodes."""
        from mlpfac.plants.terrain import pack

        return pack(self)

    def height(self, x: float, y: float) -> float:
        """The ground's height at (x, y) (m): the rough ground, the ramps and the kerbs, the highest of them."""
        from mlpfac.plants.terrain import ground_height

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
    (:data:`mlpfac.plants.terrain.BUMPS`), its heights sampled on a grid of the arena (the
    heightfield), the grid's (dx, dy) and the digest of the draw (of the nodes about the world's
    origin, and the wavelength and height: the arena's nodes are the same)."""
    from mlpfac.plants.terrain import BUMPS, W_HEAD, sample_bumps

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
