"""The Python API: what the command line does, for a notebook or a test.

    import mlpfac

    rec = mlpfac.run("eight-wheel-radius", controller=MyLaw, seed=3)   # a RunRecord
    mlpfac.metrics(rec)["phases"]["after"]["rms_position_error_m"]
    rows = mlpfac.sweep(["eight-wheel-radius"], [MyLaw, "oracle", "corradini"], seeds="0-9")

A controller is a shipped name, ``"path/to/file.py:Class"``, ``"package.module:Class"``, an
installed name, a class, or (for :func:`run`) an object of a class (:mod:`mlpfac.control.plugins`).
"""

from __future__ import annotations

import shutil
import tempfile
import warnings
from pathlib import Path

from mlpfac.control.plugins import local_spec
from mlpfac.exceptions import ConfigError, MlpfacError
from mlpfac.io.targets import user_path
from mlpfac.loop.record import RunRecord
from mlpfac.scenario.parse import Scenario, load
from mlpfac.sweeps.worker import not_in_a_worker


def _scenario(scenario: Scenario | str | Path, where: str = "scenario", robot: str | None = None) -> Scenario:
    if isinstance(scenario, Scenario):
        if robot is not None:
            raise ConfigError("robot", "a robot puts a scenario's file on it: give the scenario by name or path")
        return scenario
    if isinstance(scenario, bool) or not isinstance(scenario, str | Path):
        raise ConfigError(where, f"expected a Scenario, a shipped scenario's name or a .toml path, got {scenario!r}")
    return load(scenario, robot=robot)


def _seeds(seeds) -> str:
    """``seeds`` as the text --seeds takes: "0-9", a whole number, or a list of whole numbers."""
    if isinstance(seeds, str):
        return seeds
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        return str(seeds)
    if isinstance(seeds, list | tuple | range) and all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        return ",".join(str(s) for s in seeds)
    raise ConfigError("seeds", f'expected "0-9", a whole number or a list of whole numbers, got {seeds!r}')


def _spec(controller, where: str) -> str:
    """A controller as a name the scenario table holds."""
    if isinstance(controller, str | Path):
        return str(controller)
    if isinstance(controller, type):
        return local_spec(controller)
    raise ConfigError(where, f"expected a controller's name or class, got {controller!r}")


def run(
    scenario: Scenario | str | Path,
    controller=None,
    *,
    seed: int | None = None,
    duration: float | None = None,
    out: str | Path | None = None,
    figure: str | None = "corradini",
    record: bool = True,
    sink=None,
    on_step=None,
    robot: str | None = None,
    lost_threshold: float | None = None,
) -> RunRecord:
    """One closed-loop run of ``scenario`` (a :class:`Scenario`, a shipped name or a .toml path).

    ``controller`` overrides the scenario's: a name (as ``--controller``), a class (built as
    ``Class(T=..., **params)``) or an object of one, which is run as it is (its ``reset(rng)`` is
    called first). With ``out``, the run's folder is written as ``mlpfac run --out`` writes it:
    config.toml, metrics.json, figure1.png (panel (h) from a run of ``figure``, None: no figure) and
    run.rrd (``record``), put in place only when whole. Without it, ``sink`` (:mod:`mlpfac.log`)
    may receive the recording and ``on_step(k)`` is called after every step. A status "diverged"
    or "interrupted" keeps what was recorded; what a user's controller raises is a
    :class:`~mlpfac.exceptions.PluginError`. ``robot`` puts the scenario on that robot (as ``--robot``);
    ``lost_threshold`` sets its ``lost_threshold_m`` (as ``--lost-threshold``).
    """
    from mlpfac.loop.runner import build
    from mlpfac.loop.runner import run as run_scenario

    not_in_a_worker("run")
    scn = _scenario(scenario, robot=robot)
    instance = None
    if controller is not None and not isinstance(controller, str | Path | type):
        instance, controller = controller, type(controller)
    spec = None if controller is None else _spec(controller, "controller")
    if lost_threshold is not None:
        from mlpfac.scenario.parse import lost_threshold_m

        lost_threshold = lost_threshold_m(lost_threshold, "lost_threshold")
    scn = scn.with_overrides(spec, seed, duration, flag="controller", lost_threshold=lost_threshold)
    if out is not None:
        out = user_path(out, "out")
    if out is None:
        return run_scenario(scn, sink=sink, on_step=on_step, built=build(scn, instance))
    if sink is not None or on_step is not None:
        raise ConfigError("out", "a run into a folder records into it: give out, or sink / on_step, not both")
    from mlpfac.runs.folder import Recording, check_outputs, run_into_folder

    baseline = None
    if figure is not None:
        try:
            baseline = scn.with_overrides(controller=figure, flag="figure")
        except ConfigError as err:
            raise ConfigError("figure", err.what) from None
    recording = check_outputs(Path(out), Recording(off=not record))
    return run_into_folder(scn, Path(out), build(scn, instance), recording, baseline).rec


def sweep(
    scenarios,
    controllers=None,
    seeds: str | int | list[int] = "0-9",
    *,
    out: str | Path | None = None,
    duration: float | None = None,
    workers: int | None = None,
    batched: bool = False,
    batch_size: int = 64,
    scheduler: str | None = None,
    save_rrd: bool = False,
    robots: list[str] | None = None,
    vary: dict | list[str] | None = None,
    threshold: float | None = None,
    lost_threshold: float | None = None,
    limit: bool = False,
    limit_cache: str | Path | None = None,
) -> list[dict]:
    """Run scenarios x controllers x seeds (as ``mlpfac sweep``) and return the sweep's rows: the
    ``rows`` of sweep.json, one per scenario, controller and phase. With ``out`` the folder is
    written as the command writes it (and resumed: runs already done are not run again); without,
    the runs are made in a temporary folder that is removed. ``controllers`` None: each scenario's
    own. A class no file or module names (defined in a notebook) runs in this process only.
    ``vary`` is ``--vary``: ``{"events.0.scale": [1.0, 1.5, 2.0]}`` (or ``"1.0:2.0:5"``) an axis, two a
    grid; ``{"plant.pose_noise_std": {"uniform": [0.0, 0.002]}}`` (or ``"uniform:0:0.002"``) drawn
    per seed; with an axis, ``out`` also gets robustness.json / .md / .png (breaking points within
    ``threshold`` metres; default the tracking limit), and ``.robustness`` holds robustness.json.

    The returned list has ``.errors`` ({(scenario, controller, seed): traceback}) and ``.paired``
    (the rows of paired.json). Ctrl-C raises KeyboardInterrupt (with ``out``, the runs written are
    kept and the next call resumes them). ``robots``: every scenario on each (as ``--robots``);
    ``lost_threshold``: every run's ``lost_threshold_m`` (as ``--lost-threshold``). ``limit`` (as
    ``--limit``): the physical limit on every scenario and seed, each computed once and kept in
    ``limit_cache`` (default ``runs/limits``); the paired rows gain ``x_limit_median``."""
    from mlpfac.plots.robustness import read_robustness
    from mlpfac.scenario.on_robot import robots_named, with_robots
    from mlpfac.sweeps import engine

    not_in_a_worker("sweep")
    if isinstance(scenarios, str | Path):
        scenarios = [scenarios]
    if not isinstance(scenarios, list | tuple) or not all(isinstance(s, str | Path) for s in scenarios):
        raise ConfigError("scenarios", f"expected a scenario's name or path, or a list of them, got {scenarios!r}")
    seeds = _seeds(seeds)
    for name, value in (("workers", workers), ("batch_size", batch_size)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            raise ConfigError(name, f"expected a whole number, got {value!r}")
    if scheduler is not None and not isinstance(scheduler, str):
        raise ConfigError("scheduler", f"expected a Dask scheduler's address (str), got {scheduler!r}")
    if robots is not None and (not isinstance(robots, list | tuple) or not all(isinstance(r, str) for r in robots)):
        raise ConfigError("robots", f"expected a list of robots (names or files), got {robots!r}")
    if out is not None:
        out = user_path(out, "out")
    if not isinstance(limit, bool):
        raise ConfigError("limit", f"expected True or False, got {limit!r}")
    if limit_cache is not None:
        if not limit:
            raise ConfigError("limit_cache", "is the cache of limit's runs: give it with limit=True")
        limit_cache = user_path(limit_cache, "limit_cache")
    text = None
    if controllers is not None:
        specs = [
            _spec(c, "controllers")
            for c in ([controllers] if isinstance(controllers, str | Path | type) else _listed(controllers))
        ]
        workers = 2 if workers is None else workers
        if any(s.startswith("<local>:") for s in specs) and (scheduler or workers > 1):
            warnings.warn("a class defined in this session runs in this process only (workers=1)", stacklevel=2)
            workers, scheduler = 1, None
        text = ",".join(specs)
    tmp = None if out is not None else Path(tempfile.mkdtemp(prefix="mlpfac-sweep-"))
    try:
        with robots_named("robots"):  # a robot's errors name this argument
            result = engine.sweep_folder(
                with_robots([str(s) for s in scenarios], robots),
                text,
                seeds,
                Path(out) if out is not None else tmp,
                duration=duration,
                workers=workers if workers is not None else 2,
                batched=batched,
                batch_size=batch_size,
                scheduler=scheduler,
                save_rrd=save_rrd,
                progress=False,
                vary=vary,
                threshold=threshold,
                lost_threshold=lost_threshold,
                limit=limit,
                limit_cache=Path(limit_cache) if limit_cache is not None else None,
            )
        robust = Path(out if out is not None else tmp) / "robustness.json"
        robustness = read_robustness(robust) if robust in result.paths else None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    if result.outcome.interrupted:
        raise KeyboardInterrupt
    if result.code is not None:  # a local worker process died (said on stderr)
        raise MlpfacError("a sweep worker process died; every run written is whole: run the sweep again to resume")
    rows = Rows(result.rows)
    rows.errors, rows.paired, rows.robustness = dict(result.outcome.errors), result.paired, robustness
    return rows


def _listed(controllers) -> list:
    if not isinstance(controllers, list | tuple):
        raise ConfigError("controllers", f"expected a controller, or a list of them, got {controllers!r}")
    return list(controllers)


class Rows(list):
    """The rows of a sweep, with its failed runs (``errors``), its paired rows (``paired``) and,
    with a ``vary`` axis, its curves and breaking points (``robustness``, as robustness.json)."""

    errors: dict
    paired: list
    robustness: dict | None
