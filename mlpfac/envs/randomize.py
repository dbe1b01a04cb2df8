"""``randomize={"events.0.scale": "uniform:1.2:1.8", ...}``: numbers of the scenario drawn per episode.

A key is the dotted path of a number of the scenario file, a value a distribution in the syntax
``--vary`` draws with (``uniform:LOW:HIGH``, ``normal:MEAN:SD``, or ``{"uniform": [LOW, HIGH]}``):
:mod:`mlpfac.sweeps.vary` checks them (a key that is no number of the file is refused, naming the keys
that are; both ends of each distribution are built once), and the episode's seed draws them as a
sweep's seed does (:mod:`mlpfac.scenario.draws`: from (seed, key) alone), so episode seed s is the
robot ``mlpfac sweep SCENARIO --vary KEY=DIST --seeds s`` runs.
"""

from __future__ import annotations

from mlpfac.exceptions import ConfigError
from mlpfac.scenario.parse import Scenario, load
from mlpfac.sweeps.vary import FLAG, grid, parse_vary

WHERE = "randomize"


def randomized_source(
    src: str, robot: str | None, randomize: dict | None, duration: float | None
) -> tuple[Scenario, tuple[str, ...]]:
    """The scenario ``src`` (on ``robot``) with a distribution at each randomized key, and the keys.
    A bad key or distribution is a ConfigError naming ``randomize KEY``."""
    if randomize is None:
        return load(src, robot=robot), ()
    if not isinstance(randomize, dict):
        raise ConfigError(WHERE, f'expected {{KEY: "uniform:LOW:HIGH" or "normal:MEAN:SD"}}, got {randomize!r}')
    try:
        vary = parse_vary(randomize)
        for axis in vary.axes:
            raise ConfigError(
                f"{FLAG} {axis.key}",
                f"{axis.text.partition('=')[2]!r} is a list of values; an episode draws its number: give a "
                "distribution, uniform:LOW:HIGH or normal:MEAN:SD",
            )
        ((_, scn),) = grid(src, vary, duration, robot)
    except ConfigError as err:
        where, what = (x.replace(FLAG, WHERE).replace("--duration", "duration") for x in (err.where, err.what))
        raise type(err)(where, what) from None
    return scn, tuple(vary.draws)
