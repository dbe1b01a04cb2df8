"""docs/scenario-file.md written from the code that reads a scenario file: every table and key, its
type, default and range as the validators give them (probed with values around 0 and 1, so a new
check shows here by itself), its meaning from the comment beside the dataclass field. Keys the
validators accept but this module does not describe are an error, so the page cannot lag behind
(``python -m mlpfac.pages docs --check``, run by tests/test_docs.py)."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import io
import math
import re
import textwrap
import tokenize
import types
import typing

from mlpfac.exceptions import ConfigError
from mlpfac.scenario.own_reference import OWN_KEYS
from mlpfac.scenario.waypoints import PATH_KEYS, RANGES
from mlpfac.tables import build

HEAD = "<!-- Written by `python -m mlpfac.pages docs` from the code; edit the code, not this page. -->\n"

# The scenario-level keys and the tables without a dataclass of their own: key -> (unit, meaning)
TOP = {
    "name": ("", "the scenario's name: its run folders and its rows in tables (default: the file's name)"),
    "description": ("", "one line, shown by `mlpfac list`"),
    "duration": ("s", "the run's length (`--duration` overrides it)"),
    "T": ("s", "the control period: the controller runs once every T"),
    "seed": ("", "the run's seed: noise, initial weights and the controller's stream (`--seed` overrides it)"),
    "warmup": ("s", "seconds at the start left out of the phase figures of `metrics.json` (the networks learn)"),
    "divergence_m": ("m", "a position error beyond this ends the run as diverged"),
    "lost_threshold_m": (
        "m",
        "a finished run whose phase's position RMS is beyond this is lost (`--lost-threshold` overrides it)",
    ),
    "reference": ("", "the path to track: [below](#reference)"),
    "initial": ("", "where the robot starts: [below](#initial)"),
    "plant": ("", "the robot: [below](#plant)"),
    "controller": ("", "the controller and its options: [below](#controller)"),
    "events": ("", "changes of the robot mid-run, never told to the controller: [below](#events)"),
    "world": ("", "the ground around the robot from the start: ramps, rough ground, floor patches: [below](#world)"),
    "provenance": ("", "written by mlpfac into a run's `config.toml` (what was simulated); not for a file of yours"),
    "drawn": (
        "",
        "written by mlpfac into a run's `config.toml`: the value each distribution of the file drew for this seed "
        "(checked again when it re-runs); not for a file of yours",
    ),
}
INITIAL = {
    "error": ("m, m, rad", "the initial tracking error (e1, e2, e3) of (2) from the reference's pose at t = 0"),
    "moving": ("", "the robot starts with the reference's (v_r, ω_r); false: at rest"),
}
CONTROLLER = {
    "name": (
        "",
        "`adaptive` (default), a shipped controller (`mlpfac list`), `file.py:Class` (from this file's folder) or `module:Class`",
    ),
    "adaptive": ("", "the adaptive scheme's options: [below](#controlleradaptive)"),
    "kanayama": ("", "Kanayama's gains: [below](#controllerkanayama)"),
    "mpc": ("", "the planner's and the estimator's settings of `mpc` and `limit`: [below](#controllermpc)"),
    "params": ("", "keyword arguments of your own controller's class (`Class(T=..., **params)`); a plug-in only"),
}
PATH = {  # [reference] kind = "path" (mlpfac.scenario.waypoints): key -> (unit, meaning)
    "points": ("m", "the waypoints, `[[x, y], ...]`: at least 2 (3 closed), none repeated, no turn back on itself"),
    "file": (
        "",
        "or a CSV file of them (x and y in m, one a line, a header line allowed; no heading or time column), "
        "from this file's folder",
    ),
    "closed": ("", "the route returns to its first waypoint and loops (default false: it ends, then goes straight on)"),
    "radius": (
        "m",
        "a right-angle corner's smallest radius of curvature (default: max(v_max / (2 omega_max), track / 2, 1 mm))",
    ),
    "v_max": (
        "m/s",
        "each wheel's rim speed |v| + |ω| track / 2 (and |v|) at most this (default: 0.5 of the controller's v_max; on a MuJoCo robot 0.5 of its wheels' limit)",
    ),
    "omega_max": (
        "rad/s",
        "|ω| at most this (default: 0.5 of the controller's omega_max; on a MuJoCo robot 2 v_max / track)",
    ),
    "a_max": (
        "m/s²",
        "each wheel's rim acceleration |dv| + |dω| track / 2 at most this (default: v_max / 1 s; on a MuJoCo robot 0.5 of what its wheels' torque gives, at most its speed limit / 1 s)",
    ),
    "alpha_max": ("rad/s²", "|dω| at most this (default: omega_max / 1 s; on a MuJoCo robot 2 a_max / track)"),
    "track": (
        "m",
        "the wheels' track coupling v and ω in the limits (default 0: apart, as on the kinematic model; on a MuJoCo robot its own)",
    ),
    "speed": ("x", "the same path traversed this many times as fast (v, ω x speed, their rates x speed²)"),
}
OWN = {
    "params": ("", "keyword arguments of your own reference class (`Class(**params)`): `[reference.params]`"),
    "speed": ("x", "the same reference traversed this many times as fast (default 1, at most 100)"),
}
PLACED = {k: {"x": 0.0, "y": 0.0, "height": 0.005, "length": 0.3} for k in ("x", "y", "heading_deg")}  # (x, y), not at
# keys whose checks depend on another key: probed with that one set
CONTEXT = {"detect_mean": {"detect": 1.0}, "input_P_alarm": {"detect": 1.0, "detect_mean": 1.0}}


def _known(table: dict, where: str) -> set[str]:
    """The keys a table accepts, as the validator names them for an unknown one."""
    from mlpfac.scenario.parse import parse

    try:
        parse(table)
    except ConfigError as err:
        m = re.search(r"\(known: ([^)]*)\)", err.what)
        if m:
            return set(m[1].split(", "))
    raise AssertionError(f"{where}: the validator did not name its keys")


def _rejects(make, key: str, value) -> str | None:
    """The validator's message when ``key = value`` is refused because of that key, else None."""
    try:
        make(value)
    except ConfigError as err:
        if key in err.where.split():
            return err.what
    except (TypeError, ValueError) as err:
        return str(err)
    return None


def _range(make, key: str, hint, bounds: tuple[float, ...] = ()) -> str:
    """The values accepted, probed: bounds at -1, 0 or 1 (or at ``bounds``, a field's declared ones;
    open or closed), inf, or the validator's choices."""
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    base = typing.get_args(hint) if union else (hint,)
    if str in base and float not in base:
        what = _rejects(make, key, "?")
        return what.split(", got")[0] if what and what.startswith("choose") else ""
    if bool in base:
        return ""
    scalar = int if int in base and float not in base else float
    tup = next((h for h in base if typing.get_origin(h) is tuple), None) if scalar not in base else None
    n = 0 if tup is None else (3 if typing.get_args(tup)[-1] is Ellipsis else len(typing.get_args(tup)))

    def ok(v) -> bool:
        return _rejects(make, key, [v] * n if n else v) is None

    if scalar is int:
        lo = next((v for v in (-1, 0, 1, 2) if ok(v)), None)
        if lo is None:
            return ""
        if ok(10**6):
            return "" if lo == -1 else f">= {lo}"
        hi, top = lo, 10**6
        while top - hi > 1:
            mid = (hi + top) // 2
            hi, top = (mid, top) if ok(mid) else (hi, mid)
        return f"{lo}-{hi}"
    eps, lower, upper = 1e-9, "", ""
    if not ok(-1e9):
        for t in (-1.0, 0.0, 1.0, *bounds):
            if not ok(t - eps) and ok(t + eps):
                lower = ("[" if ok(t) else "(") + f"{t:g}"
                break
    if not ok(1e9):
        for t in (1.0, 0.0, -1.0, *bounds):
            if ok(t - eps) and not ok(t + eps):
                upper = f"{t:g}" + ("]" if ok(t) else ")")
                break
    text = f"{lower}, {upper}" if lower and upper else ""
    if not text:
        text = ("> " if lower[:1] == "(" else ">= ") + lower[1:] if lower else ""
        text = text or (("< " if upper[-1:] == ")" else "<= ") + upper[:-1] if upper else "")
    if ok(math.inf):
        text += ("; " if text else "") + "`inf`: no limit"
    return text


def _type(hint) -> str:
    """A field's TOML type in a few words: number, integer, bool, string, 3 numbers, ..."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join(_type(h) for h in typing.get_args(hint) if h is not type(None))
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if args[-1] is Ellipsis:
            return "3x3 numbers" if typing.get_origin(args[0]) is tuple else "3 numbers"
        return f"{len(args)} numbers"
    return {bool: "bool", int: "integer", float: "number", str: "string"}.get(hint, str(hint))


def _comments(cls) -> dict[str, str]:
    """field name -> the comment written beside it in the source of the class or of the dataclass it
    builds on (``# noqa: X --`` dropped)."""
    bases = [b for b in cls.__mro__[1:] if dataclasses.is_dataclass(b)]
    out = {k: v for b in reversed(bases) for k, v in _own_comments(b).items()}
    return out | _own_comments(cls)


def _own_comments(cls) -> dict[str, str]:
    """field name -> the comment beside it in ``cls``'s own source."""
    src = textwrap.dedent(inspect.getsource(cls))
    notes: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type == tokenize.COMMENT:
            text = tok.string.lstrip("# ").strip()
            notes[tok.start[0]] = re.sub(r"^noqa: \S+ --\s*", "", text)
    out = {}
    for node in ast.parse(src).body[0].body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            lines = range(node.lineno, (node.end_lineno or node.lineno) + 1)
            out[node.target.id] = " ".join(notes[i] for i in lines if i in notes)
    return out


def _default(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        val = f.default
    elif f.default_factory is not dataclasses.MISSING:
        val = f.default_factory()
    else:
        return "required"
    if val is None:
        return "none"
    if isinstance(val, bool):
        return "true" if val else "false"
    if isinstance(val, str) and f.default_factory is not dataclasses.MISSING:  # a path: the shipped file
        parts = val.replace("\\", "/").split("/")
        return "`" + "/".join(parts[-2:]) + "`"
    if isinstance(val, str):
        return f'"{val}"'
    if isinstance(val, tuple):
        return "[" + ", ".join(f"{x:g}" for x in val) + "]"
    return f"{val:g}" if isinstance(val, float) else str(val)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _dataclass_rows(
    cls, where: str, skip: frozenset = frozenset(), base: dict | None = None, apart: dict | None = None
) -> list[str]:
    """One row a field of ``cls``; ``base``: values of its required fields, beside the one probed;
    ``apart``: another base for the keys it names (where the base's own keys exclude them)."""
    hints, notes = typing.get_type_hints(cls), _comments(cls)
    rows = ["| key | type | default | range | meaning |", "| --- | --- | --- | --- | --- |"]
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue

        def make(v, key=f.name):
            return build(cls, (apart or {}).get(key, base or {}) | CONTEXT.get(key, {}) | {key: v}, where)

        p = f.metadata.get("param")
        bounds = () if p is None else tuple(b for b in (p.minimum, p.maximum) if b is not None)
        bounds = bounds or tuple(getattr(cls, "LIMITS", {}).get(f.name, ()))  # a class's declared ranges
        cells = (f"`{f.name}`", _type(hints[f.name]), _default(f), _range(make, f.name, hints[f.name], bounds))
        rows.append("| " + " | ".join(_cell(c) for c in (*cells, notes.get(f.name, ""))) + " |")
    return rows


def _plain_rows(described: dict, known: set[str], where: str, probe=None) -> list[str]:
    missing, extra = known - set(described), set(described) - known
    if missing or extra:
        raise AssertionError(f"{where}: keys not described {sorted(missing)}, described but unknown {sorted(extra)}")
    rows = ["| key | unit | default | range | meaning |", "| --- | --- | --- | --- | --- |"]
    for key, (unit, meaning) in described.items():
        default, rng = probe(key) if probe else ("", "")
        rows.append(f"| `{key}` | {unit} | {default} | {_cell(rng)} | {_cell(meaning)} |")
    return rows


def _top_probe(key: str) -> tuple[str, str]:
    """The default and range of a scenario-level number, from :func:`mlpfac.scenario.parse` itself."""
    from mlpfac.scenario.parse import parse

    if key not in ("duration", "T", "seed", "warmup", "divergence_m", "lost_threshold_m"):
        return {"name": ("the file's name", "letters, digits, `.` `_` `+` `-`")}.get(key, ("", ""))
    if key == "lost_threshold_m":  # unset: a share of the path's size (mlpfac.loop.metrics)
        return "5 % of the path's size", _range(lambda v: parse({key: v}), key, float)
    default = getattr(parse({}), key)
    if key == "duration":  # bounded below by T, above by the memory a run may take
        return f"{default:g}", ">= T; its steps must fit in memory"
    ctx = {"T": {"duration": 1e9}}.get(key, {})
    hint = int if key == "seed" else float
    return f"{default:g}", _range(lambda v: parse(ctx | {key: v}), key, hint)


def _path_probe(key: str) -> tuple[str, str]:
    """The range of a path's number, from :func:`mlpfac.scenario.waypoints.make_path` itself."""
    from mlpfac.scenario.waypoints import make_path

    if key not in RANGES:
        return {"closed": ("false", ""), "points": ("", "within +-10000 m; at most 1000")}.get(key, ("", ""))
    base = {"points": [[0.0, 0.0], [1.0, 0.0]]}
    most, unit = RANGES[key]
    if key == "radius":  # 0 (from the limits), or a corner the spline can draw
        from mlpfac.scenario.path import MIN_RADIUS

        return "", f"0, or >= {MIN_RADIUS:g}, <= {most:g}"
    low = _range(lambda v: make_path(base | {key: v}, "[reference]"), key, float)
    return ("1" if key == "speed" else ""), f"{low}, <= {most:g}"


def _initial_probe(key: str) -> tuple[str, str]:
    """The default of an ``[initial]`` key, as :func:`mlpfac.scenario.parse` fills it in."""
    from mlpfac.scenario.parse import parse

    scn = parse({})
    if key == "error":
        return "[" + ", ".join(f"{x:g}" for x in scn.initial_error) + "]", "finite"
    return ("true" if scn.start_moving else "false"), ""


def _rules(cls) -> str:
    """The rules between an event's parameters that its validator enforces (``APART``: at most one of
    them; ``NEEDS``: one needs another), in words for the page."""
    apart = [f"{', '.join(f'`{k}`' for k in keys)} ({why})" for keys, why in getattr(cls, "APART", ())]
    needs = [
        f"`{key}` needs {' or '.join(f'`{o}`' for o in others)} ({why})"
        for key, others, why in getattr(cls, "NEEDS", ())
    ]
    out = f" At most one of each: {'; '.join(apart)}." if apart else ""
    return out + (f" {'; '.join(needs)}." if needs else "")


def scenario_page() -> str:
    from mlpfac.control.adaptive.config import AdaptiveConfig
    from mlpfac.control.adaptive.networks import Networks
    from mlpfac.control.baselines import KanayamaGains
    from mlpfac.control.law import Law
    from mlpfac.control.mpc.config import MpcConfig
    from mlpfac.plants.config import MujocoConfig
    from mlpfac.plants.events import EVENTS, MU_MAX
    from mlpfac.plants.kinematic import KinematicConfig, KinematicPlant
    from mlpfac.plants.mujoco.holds import STEP_SHARE
    from mlpfac.plants.world.table import FEATURES_MAX, Bumps, Kerb, Patch, Ramp
    from mlpfac.scenario.reference import REFERENCES

    out = [
        "# The scenario file, key by key",
        "",
        HEAD,
        (
            "A scenario is a TOML file (`sims/*.toml` are the shipped ones; [Scenarios](scenarios.md)). Every key is "
            "optional; a key or table not listed here is an error, and so is a value of the wrong type or out of range: "
            "one line naming the file and key, exit 2, before anything runs. Ranges: `(0, 1]` is 0 < x <= 1; "
            "`> 0` positive. Units are SI (m, s, rad) unless a key says otherwise."
        ),
    ]
    out += ["", "## The scenario's own keys", "", *_plain_rows(TOP, _known({"x": 1}, "top"), "top", _top_probe)]
    out += [
        "",
        "## `[reference]`",
        "",
        '`kind` (default `"eight"`) picks the path; the other keys are its '
        "parameters (finite numbers). The reference speed v_r must stay above zero along the path.",
    ]
    for kind, cls in REFERENCES.items():
        rows = _dataclass_rows(cls, "[reference]")
        doc = " ".join(inspect.cleandoc(cls.__doc__ or "").split()).replace("``", "`")
        out += ["", f'### `kind = "{kind}"`', "", doc, "", *rows]
    out += [
        "",
        '### `kind = "path"`: your own path',
        "",
        "Waypoints, each corner rounded (a quintic B-spline: ω continuous) and the route timed so that each "
        "wheel's speed and acceleration stay within the limits below: "
        "[Your own path](scenarios.md#your-own-path). On a MuJoCo robot the limits it leaves unset are its robot's, "
        "written into the run's `config.toml`.",
        "",
        *_plain_rows(PATH, set(PATH_KEYS), '[reference] kind = "path"', _path_probe),
        "",
        '### `kind = "file.py:Class"`: your own reference class',
        "",
        "A class built as `Class(**[reference.params])` whose `sample(t)` returns (x, y, θ, v, ω, dv, dω): "
        "[Your own reference class](scenarios.md#your-own-reference-class). `file.py` is taken from this file's "
        "folder; `package.module:Class` is imported.",
        "",
        *_plain_rows(OWN, set(OWN_KEYS), "[reference] (your own class)"),
    ]
    out += ["", "## `[initial]`", ""]
    out += _plain_rows(INITIAL, _known({"initial": {"x": 1}}, "[initial]"), "[initial]", _initial_probe)
    out += [
        "",
        "## `[plant]`",
        "",
        '`kind` (default `"kinematic"`) picks the plant.',
        "",
        '### `kind = "kinematic"`: the model (7)',
        "",
        *_dataclass_rows(KinematicConfig, "[plant]"),
    ]
    out += [
        "",
        '### `kind = "mujoco"`: a MuJoCo robot',
        "",
        "What each key does to the robot: "
        "[`models/README.md`](../models/README.md#mujococonfig-the-plant-table-of-a-scenario).",
        "",
        *_dataclass_rows(MujocoConfig, "[plant]"),
    ]
    known = _known({"controller": {"x": 1}}, "[controller]")
    law = {f.name for f in dataclasses.fields(Law)}
    out += [
        "",
        "## `[controller]`",
        "",
        *_plain_rows(CONTROLLER, known - law, "[controller]"),
        "",
        "The law (35)'s keys, for every controller built on it:",
        "",
        *_dataclass_rows(Law, "[controller]"),
    ]
    out += [
        "",
        "### `[controller.adaptive]`",
        "",
        "The adaptive scheme and its variants "
        "([Controllers](controllers.md#beyond-the-paper-the-adaptive-variants)); a named variant "
        "(`adaptive-best`, ...) sets some of these itself. The networks' sizes:",
        "",
        *_dataclass_rows(Networks, "[controller.adaptive]"),
        "",
        "The filter, the law and the options:",
        "",
        *_dataclass_rows(AdaptiveConfig, "[controller.adaptive]", frozenset({"networks"})),
    ]
    out += [
        "",
        "### `[controller.kanayama]`",
        "",
        "v = v_r cos e3 + Kx e1, ω = ω_r + v_r (Ky e2 + Kθ sin e3).",
        "",
        *_dataclass_rows(KanayamaGains, "[controller.kanayama]"),
        "",
        "### `[controller.mpc]`",
        "",
        "`mpc` and `limit`: model-predictive control with the run's own MuJoCo robot as the model "
        "([Controllers](controllers.md#the-physical-limit-mpc-and-limit)).",
        "",
        *_dataclass_rows(MpcConfig, "[controller.mpc]"),
    ]
    out += [
        "",
        "## `[world]`",
        "",
        "The ground around a MuJoCo robot, present from the start (the kinematic model drives on none), built into the "
        "scene the plant compiles ([Scenarios](scenarios.md#the-world-around-the-robot)). Each is checked against the "
        "robot before anything runs: a ramp its wheels cannot climb or that lies under them at the start, a kerb "
        "too high for its wheels or casters, rough ground too fine for its tyres, a patch, ramp or kerb placed outside the "
        f"arena (the reference's bounding box and 1 m around it). At most {FEATURES_MAX} ramps, {FEATURES_MAX} "
        f"kerbs and {FEATURES_MAX} patches.",
        "",
        "`over` (s, > 0; default: the run's `duration`): the seconds of the reference the world is laid out along "
        "(its arena, where the ramps' and kerbs' `at` falls), its samples within the memory available as a run's "
        "steps are; `--duration` writes the file's into `config.toml`, so that a shorter run drives into the same "
        "world.",
        "",
        "`ramps`: a list of tables, ramps (up, a flat top, down, each a third of `length`), across the path at "
        "`at` of it, or placed at (`x`, `y`) as patches are, heading `heading_deg`:",
        "",
        *_dataclass_rows(Ramp, "[world] ramps", base={"at": 0.5, "height": 0.01, "length": 1.0}, apart=PLACED),
        "",
        "`kerbs`: a list of tables, kerbs: slabs with vertical edges, a step up where the path meets one and a "
        "step down `length` further on, placed as ramps are. Each at most "
        f"{STEP_SHARE:.2f} of the radius of the robot's smallest wheel or caster (higher, the step's edge pushes "
        f"it back more than {MU_MAX:g} times as hard as up: a tyre would need a friction beyond the most a scenario "
        "takes; at the axle's height the step is a wall); what the motors need to climb each "
        "from rest, a driven wheel carrying W at its edge: W sqrt(2 r h - h²) about its axle, W tan(a) a caster "
        "pushed up it, tan(a) = sqrt(2 r h - h²) / (r - h) (r its radius, h the step's height), said in the run's "
        "`[provenance] world`, and on its first line where the motors, the tyres' friction or the chassis' "
        "clearance fall short:",
        "",
        *_dataclass_rows(Kerb, "[world] kerbs", base={"at": 0.5, "height": 0.005, "length": 0.3}, apart=PLACED),
        "",
        "`bumps`: a table, rough ground over the arena: a heightfield drawn per seed (its digest in `[drawn]`):",
        "",
        *_dataclass_rows(Bumps, "[world] bumps", base={"height": 0.01, "wavelength": 0.3}),
        "",
        "`patches`: a list of tables, floor patches of their own friction, flush with the floor:",
        "",
        *_dataclass_rows(Patch, "[world] patches", base={"x": 0.0, "y": 0.0, "radius": 0.1, "mu": 0.5}),
    ]
    kin = KinematicPlant.supported_events
    out += [
        "",
        "## `[[events]]`",
        "",
        "One table per event: `time` (s, >= 0, before `duration`) and `kind`, then "
        "the kind's parameters. A MuJoCo robot takes every kind; the kinematic plant "
        f"{', '.join(f'`{k}`' for k in sorted(kin))}.",
        "",
        "| kind | parameters | what it does |",
        "| --- | --- | --- |",
    ]
    for kind, cls in EVENTS.items():
        doc = _cell(" ".join(inspect.cleandoc(cls.__doc__ or "").split()).replace("``", "`") + _rules(cls))
        params = []
        for f in dataclasses.fields(cls):
            p = f.metadata.get("param")
            if p is not None:
                rng = " > 0" if p.positive else (f" >= {p.minimum:g}" if p.minimum is not None else "")
                typ = {float: "number", int: "integer", str: "name"}[p.kind]
                params.append(f"`{f.name}` ({typ}{rng}{'' if p.required else ', optional'})")
        out.append(f"| `{kind}` | {', '.join(params)} | {doc} |")
    return "\n".join(out) + "\n"
