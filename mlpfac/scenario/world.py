"""A scenario's ``[world]`` over its run: the terrain resolved from the reference over the whole
run and the run's seed (:func:`mlpfac.plants.world.layout.resolve`, once, so that every plant of the run
and its probes build the same world), and what was drawn of it recorded in the table's ``[drawn]``
(the rough ground's digest, ``world.bumps``), checked against a fresh draw when a config.toml runs
again, as a distribution's draw is (:mod:`mlpfac.scenario.draws`)."""

from __future__ import annotations

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import pose_from_error
from mlpfac.plants.world.layout import Terrain, resolve
from mlpfac.plants.world.table import World
from mlpfac.scenario.reference import sample

BUMPS_DRAWN = "world.bumps"  # [drawn]: the digest of the rough ground drawn for the seed
SAMPLE_BYTES = 128  # bytes a reference's sample takes as the world is laid out (measured: 16 floats at the peak)


def ground(
    world: World, plant_kind: str, reference, span: float, T: float, e0, seed: int, source: str
) -> Terrain | None:
    """The terrain of ``world`` laid out along ``span`` s of ``reference`` (the run's duration, or the
    file's under ``--duration``: ``[world] over``) from the initial error ``e0``, for ``seed`` (None
    for an empty world); the kinematic model is refused one."""
    if not world:
        return None
    if plant_kind != "mujoco":
        raise ConfigError(
            f"{source} [world]",
            'the kinematic model drives on no ground: [world] needs a robot ([plant] kind = "mujoco")',
        )
    ref = sample(reference, np.arange(int(round(span / T)) + 1) * T)
    start = pose_from_error(np.array(e0, dtype=float), ref[0])
    return resolve(world, ref, start, seed, f"{source} [world]")


def recorded_bumps(table: dict, source: str) -> tuple[dict, str | None]:
    """The table without its ``[drawn]`` digest of the rough ground (not a distribution's draw, which
    :func:`mlpfac.scenario.draws.resolve` checks), and that digest (None: none)."""
    drawn = table.get("drawn")
    if not isinstance(drawn, dict) or BUMPS_DRAWN not in drawn:
        return table, None
    rest = {k: v for k, v in drawn.items() if k != BUMPS_DRAWN}
    out = {k: v for k, v in table.items() if k != "drawn"} | ({"drawn": rest} if rest else {})
    value = drawn[BUMPS_DRAWN]
    if not isinstance(value, str):
        raise ConfigError(f"{source} [drawn] {BUMPS_DRAWN}", f"expected the digest of the rough ground, got {value!r}")
    return out, value


def recorded(table: dict, terrain: Terrain | None, was: str | None, seed: int, source: str) -> dict:
    """``table`` with the rough ground drawn recorded in ``[drawn]``; a digest ``was`` recorded before
    (a config.toml's) that is not this draw's is a ConfigError."""
    if terrain is None or not terrain.digest:
        return table
    digest = f"sha256:{terrain.digest}"
    if was is not None and was != digest:
        raise ConfigError(
            f"{source} [drawn] {BUMPS_DRAWN}",
            f"{was!r} is not the rough ground seed {seed} draws ({digest}): another mlpfac or numpy draws it "
            "otherwise; remove the line to run the ground drawn now",
        )
    return {**table, "drawn": {**table.get("drawn", {}), BUMPS_DRAWN: digest}}


def said(world: World, terrain: Terrain | None) -> str:
    """What was built of ``world`` for a run, in words (the run's ``world:`` line): each ramp and
    kerb where it lies, the rough ground, each patch; "" for an empty world."""
    if terrain is None:
        return ""
    import math

    def where(feature, placed) -> str:
        if feature.at is None:
            return f"at ({feature.x:g}, {feature.y:g}) m heading {feature.heading_deg or 0.0:g} deg"
        return f"across the path at ({placed.x:.3g}, {placed.y:.3g}) m ({feature.at * 100:.3g} % of the path)"

    parts = []
    for ramp, placed in zip(world.ramps, terrain.ramps, strict=False):
        slope = math.degrees(math.atan(ramp.slope))
        parts.append(
            f"a ramp {where(ramp, placed)}, {_m(ramp.height)} high, {_m(ramp.length)} long, {_m(placed.width)} "
            f"wide ({slope:.2g} deg slopes)"
        )
    for kerb, placed in zip(world.kerbs, terrain.kerbs, strict=False):
        parts.append(
            f"a kerb {where(kerb, placed)}, a step of {_m(kerb.height)} up and {_m(kerb.length)} on down, "
            f"{_m(placed.width)} wide"
        )
    if world.bumps is not None:
        x0, y0, x1, y1 = terrain.arena
        parts.append(
            f"rough ground of heights in [0, {_m(world.bumps.height)}), crests about {_m(world.bumps.wavelength)} "
            f"apart, drawn for this seed over x {x0:.3g} .. {x1:.3g} m, y {y0:.3g} .. {y1:.3g} m"
        )
    for p in world.patches:
        parts.append(f"a patch of friction {p.mu:g} at ({p.x:g}, {p.y:g}) m, {_m(2 * p.radius)} across")
    return "; ".join(parts)


def _m(x: float) -> str:
    """A length in words: cm below a metre."""
    return f"{x * 100:.3g} cm" if x < 1.0 else f"{x:.3g} m"
