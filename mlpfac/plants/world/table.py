"""A scenario's ``[world]`` table as plain, validated data: ramps and kerbs (slabs with vertical
steps), across the path or placed at (x, y), rough ground (a heightfield drawn per seed) and floor
patches of their own friction, present from the start. Each key is typed and ranged when it is
made, as an event's are (:func:`mlpfac.plants.events.param`); what the world is on a run's robot,
laid out along its reference and drawn for its seed, is :mod:`mlpfac.plants.world.layout`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import MU_MAX, MU_MIN, check_params, param
from mlpfac.tables import build, check_keys

RAMP_HEIGHT_MAX = 0.5  # m: a ramp up to half a metre high (a loading ramp), a kerb too
# m: a ramp's or a kerb's height, at least: lower, it is within the give of MuJoCo's soft contacts
# (the shipped robot's tyres sink 0.2 mm into the floor at rest) and its mesh is too flat for
# MuJoCo's convex hull (qhull: coplanar points, or pages of warnings)
HEIGHT_MIN = 1e-3
SIZE_MIN = 1e-3  # m: a ramp's or a kerb's length and width, at least
LENGTH_MAX = 50.0  # m: a ramp's length and width, a patch's radius, at most
FEATURES_MAX = 100  # ramps, kerbs and patches each, at most: each is a geom of the scene, a mesh in the recording, and looked up every step
BUMPS_HEIGHT_MAX = 0.2  # m of rough ground, top to bottom, at most
WAVELENGTH_MIN, WAVELENGTH_MAX = 0.01, 10.0  # m between crests of the rough ground
OVER_MAX = 1e5  # s of the reference a world is laid out along, at most
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
