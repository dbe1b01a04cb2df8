"""``[reference] kind = "path"``: the waypoints (``points`` inline, or a CSV ``file``) and the
limits of a :class:`~mlpfac.scenario.path.Path`, each checked and named by its key (and a file's
errors by its line) before anything runs.

A CSV file holds one waypoint a line, x and y in metres: ``x,y`` (comma- or space-separated), a
header line naming the columns allowed (``x,y``, or more columns among which ``x`` and ``y``: an
id, a note), blank lines and lines starting with ``#`` skipped. Every row has as many values as
the header names columns (``2,5,0`` under ``x,y``, a decimal comma, is refused, naming its line).
A column that means what a path does not take from its file is refused by its name: a heading
(``yaw``, ``theta``, ``heading``, ...: the robot heads along the path, which rounds each corner
past its waypoint) or a timing (``t``, ``time``, ``v``, ``speed``, ...: the path is timed within
its limits). A relative ``file`` is taken from the scenario file's folder
(:func:`mlpfac.scenario.parse.load`); the file's sha256 is recorded in the run's ``[provenance]``,
and a config.toml whose file changed since is refused.
"""

from __future__ import annotations

import hashlib
import math
import re
from pathlib import Path as FilePath

from mlpfac.exceptions import ConfigError
from mlpfac.scenario.limits import ACCEL_TIME, SHARE
from mlpfac.scenario.path import MAX_TURN_COS, MIN_LEG, MIN_RADIUS, Path

PATH_KEYS = ("points", "file", "closed", "v_max", "omega_max", "a_max", "alpha_max", "track", "radius", "speed")
MAX_POINTS = 1000  # waypoints: a route is its corners (the timing's grid grows with each)
LENGTH_MAX = 1e4  # m, a waypoint's coordinates and the track
CSV_MAX = 64 * 2**20  # bytes of a CSV file of waypoints, at most
RANGES = {  # key: (largest, unit); each must be > 0 (track >= 0)
    "v_max": (20.0, "m/s"),
    "omega_max": (100.0, "rad/s"),
    "a_max": (100.0, "m/s^2"),
    "alpha_max": (1000.0, "rad/s^2"),
    "track": (100.0, "m"),
    "radius": (LENGTH_MAX, "m"),
    "speed": (100.0, "x"),
}


def make_path(params: dict, where: str, limits: tuple[float | None, float | None] = (None, None)) -> Path:
    """The :class:`Path` of a ``[reference]`` table (``kind`` taken out); ``limits``, the
    controller's (v_max, omega_max), give the speed limits the table leaves unset: SHARE of them
    (:mod:`mlpfac.scenario.limits`), as on every robot; the accelerations then reach them in
    ACCEL_TIME. On a MuJoCo robot the robot's own limits are written in first (``on_robot``)."""
    for key in params:
        if key not in PATH_KEYS:
            raise ConfigError(f"{where} {key}", f"not a parameter of 'path' (it takes {', '.join(PATH_KEYS)})")
    values: dict = {}
    for key, (most, unit) in RANGES.items():
        if key not in params:
            continue
        val = params[key]
        if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
            raise ConfigError(f"{where} {key}", f"expected a finite number, got {val!r}")
        if not (0 <= val <= most if key == "track" else 0 < val <= most):
            low = ">= 0" if key == "track" else "> 0"
            raise ConfigError(f"{where} {key}", f"must be {low} and at most {most:g} {unit}, got {val!r}")
        if key == "radius" and 0 < val < MIN_RADIUS:
            raise ConfigError(
                f"{where} radius",
                f"must be 0 (from the limits) or at least {MIN_RADIUS:g} m (a corner the spline can draw), got {val!r}",
            )
        values[key] = float(val)
    closed = params.get("closed", False)
    if not isinstance(closed, bool):
        raise ConfigError(f"{where} closed", f"expected true or false, got {closed!r}")
    v_ctrl, w_ctrl = (x if x is not None and math.isfinite(x) else d for x, d in zip(limits, (2.0, 5.0), strict=True))
    values.setdefault("v_max", float(f"{SHARE * v_ctrl:.6g}"))
    values.setdefault("omega_max", float(f"{SHARE * w_ctrl:.6g}"))
    values.setdefault("a_max", values["v_max"] / ACCEL_TIME)
    values.setdefault("alpha_max", values["omega_max"] / ACCEL_TIME)
    points, lines, file, sha = _points(params, where)
    points = _checked(points, lines, closed, where, file)
    try:
        return Path(points=points, closed=closed, file=file, sha256=sha, **values)
    except ConfigError as err:
        key = err.where or _culprit(params, where, limits)
        raise ConfigError(f"{where} {key}".strip(), err.what) from None


SLOWING = ("speed", "v_max", "omega_max", "a_max", "alpha_max", "radius")  # what a path's time once along it grows with


def slowest(params: dict, where: str, limits: tuple, fits) -> str | None:
    """The key of a path's ``[reference]`` table ``params`` that makes it too long to drive once
    (``fits(seconds)`` False): ``speed`` when the path fits at speed 1, else the first limit the
    table sets whose default makes it fit; None when no one key does."""
    path = make_path(params, where, limits)
    if "speed" in params and fits(path.geometry.t[-1]):
        return "speed"
    for key in SLOWING[1:]:
        if key in params:
            try:
                if fits(make_path({k: v for k, v in params.items() if k != key}, where, limits).duration):
                    return key
            except ConfigError:
                continue
    return None


def _culprit(params: dict, where: str, limits: tuple) -> str:
    """The limit the table sets without which its path can be timed ("": none alone)."""
    for key in SLOWING[1:]:
        if key in params:
            try:
                make_path({k: v for k, v in params.items() if k != key}, where, limits)
            except ConfigError:
                continue
            return key
    return ""


def _points(params: dict, where: str) -> tuple[list, list[str], str, str]:
    """The waypoints as given, what names each (``points #3``, or ``route.csv line 4``), the file and its sha256."""
    if ("points" in params) == ("file" in params):
        raise ConfigError(
            where, 'a path takes its waypoints from points = [[x, y], ...] or from file = "route.csv": give one'
        )
    if "points" in params:
        pts = params["points"]
        if not isinstance(pts, list):
            raise ConfigError(f"{where} points", f"expected a list of [x, y] waypoints, got {pts!r}")
        for i, p in enumerate(pts):
            ok = isinstance(p, list | tuple) and len(p) == 2
            if not ok or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in p):
                raise ConfigError(f"{where} points", f"waypoint {i + 1}: expected [x, y] (two numbers in m), got {p!r}")
        return (
            [tuple(float(v) for v in p) for p in pts],
            [f"{where} points, waypoint {i + 1}" for i in range(len(pts))],
            "",
            "",
        )
    file = params["file"]
    if not isinstance(file, str) or not file:
        raise ConfigError(f"{where} file", f"expected the path of a CSV file of waypoints, got {file!r}")
    pts, lines, sha = read_csv(FilePath(file).expanduser(), f"{where} file")
    return pts, lines, str(FilePath(file).expanduser().resolve()), sha


def read_csv(path: FilePath, where: str) -> tuple[list[tuple[float, float]], list[str], str]:
    """A CSV file's waypoints, each one's ``file line N``, and the file's sha256; a ConfigError
    naming the file (and the line) for a file that cannot be read or a line that is not x, y."""
    from mlpfac.io.files import NotAFileError, read_regular

    try:
        data = read_regular(path, CSV_MAX)
    except FileNotFoundError:
        raise ConfigError(where, f"{path}: no such file") from None
    except NotAFileError as err:
        raise ConfigError(where, f"{path}: {err} (a CSV file of waypoints)") from None
    except OSError as err:
        raise ConfigError(where, f"{path}: cannot read ({err.strerror or err})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ConfigError(where, f"{path}: not a text file (UTF-8 CSV: x,y a line)") from None
    cols, points, names, header = None, [], [], None
    for n, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = [c.strip().strip('"').strip() for c in re.split("," if "," in line else r"[;\s]+", line.strip())]
        if cols is None and not points and not all(_is_number(c) for c in cells):
            low = [c.lower() for c in cells]
            if "x" not in low or "y" not in low:
                raise ConfigError(
                    where, f"{path} line {n}: a header line must name the columns x and y, got {line.strip()!r}"
                )
            _refuse_meant(low, cells, path, n, where)
            cols, header = (low.index("x"), low.index("y")), (n, len(cells), line.strip())
            continue
        if cols is None:
            if len(cells) != 2:
                raise ConfigError(
                    where,
                    f"{path} line {n}: expected x,y (two numbers in m), got {line.strip()!r} (more columns: name them in a header line)",
                )
            cols = (0, 1)
        if header is not None and len(cells) != header[1]:
            comma = " (a decimal comma? write 2.5, not 2,5)" if "," in line and len(cells) > header[1] else ""
            raise ConfigError(
                where,
                f"{path} line {n}: {len(cells)} values where the header on line {header[0]} names {header[1]} "
                f"columns ({header[2]!r}), got {line.strip()!r}{comma}",
            )
        try:
            x, y = float(cells[cols[0]]), float(cells[cols[1]])
        except (IndexError, ValueError):
            raise ConfigError(
                where, f"{path} line {n}: expected numbers in columns x and y, got {line.strip()!r}"
            ) from None
        points.append((x, y))
        names.append(f"{path} line {n}")
        if len(points) > MAX_POINTS:
            raise ConfigError(where, f"{path}: more than {MAX_POINTS} waypoints (a route is its corners: thin it)")
    return points, names, hashlib.sha256(data).hexdigest()


HEADING = ("yaw", "theta", "heading", "psi", "phi", "angle", "orientation", "qz", "qw")  # a column a heading is in
TIMING = ("t", "time", "stamp", "timestamp", "v", "speed", "velocity", "omega")  # ... the path's timing


def _refuse_meant(low: list[str], cells: list[str], path: FilePath, n: int, where: str) -> None:
    """A ConfigError naming a header's column that means what a path does not take from its file: a
    heading at each waypoint (a differential drive's heading along a path is the path's tangent,
    and the corners are rounded past their waypoints), or times and speeds (a path is timed within
    its limits). Other columns (an id, a note) are left aside."""
    for name, cell in zip(low, cells, strict=True):
        if name in HEADING:
            raise ConfigError(
                where,
                f"{path} line {n}: column {cell!r}: a path takes no heading at its waypoints (the robot heads along "
                "the path, which rounds each corner past its waypoint): remove the column; the path's heading is "
                "its tangent",
            )
        if name in TIMING:
            raise ConfigError(
                where,
                f"{path} line {n}: column {cell!r}: a path is timed within its limits ([reference] v_max, a_max, "
                "speed, ...), not by its file: remove the column",
            )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _checked(points: list, names: list[str], closed: bool, where: str, file: str) -> tuple[tuple[float, float], ...]:
    """The waypoints, checked: at least two (three for a closed route), finite, within LENGTH_MAX,
    no two consecutive closer than MIN_LEG, no turn back (a closed route's last may repeat its first)."""
    key = f"{where} file" if file else f"{where} points"
    for (x, y), name in zip(points, names, strict=True):
        if not (math.isfinite(x) and math.isfinite(y)) or max(abs(x), abs(y)) > LENGTH_MAX:
            raise ConfigError(
                key, f"{_short(name, where)}: ({x:g}, {y:g}) must be finite numbers within +-{LENGTH_MAX:g} m"
            )
    if closed and len(points) > 2 and _dist(points[0], points[-1]) < MIN_LEG:
        points, names = points[:-1], names[:-1]  # a closed route written back to its start
    least = 3 if closed else 2
    if len(points) < least:
        raise ConfigError(
            key, f"a{' closed' if closed else 'n open'} path needs at least {least} waypoints, got {len(points)}"
        )
    if len(points) > MAX_POINTS:
        raise ConfigError(key, f"{len(points)} waypoints: at most {MAX_POINTS} (a route is its corners: thin it)")
    n = len(points)
    ring = list(range(n)) + ([0] if closed else [])
    for a, b in zip(ring[:-1], ring[1:], strict=True):
        if _dist(points[a], points[b]) < MIN_LEG:
            raise ConfigError(
                key, f"{_short(names[b], where)} repeats the waypoint before it (closer than {MIN_LEG * 1e3:g} mm)"
            )
    for i in range(n) if closed else range(1, n - 1):
        (x0, y0), (x1, y1), (x2, y2) = points[i - 1], points[i], points[(i + 1) % n]
        ux, uy, wx, wy = x1 - x0, y1 - y0, x2 - x1, y2 - y1
        cos = (ux * wx + uy * wy) / (math.sqrt(ux * ux + uy * uy) * math.sqrt(wx * wx + wy * wy))
        if cos < MAX_TURN_COS:
            raise ConfigError(
                key,
                f"{_short(names[i], where)} turns the route back on itself (by more than 170 degrees): v_r stays "
                "above zero, so a path cannot reverse at a waypoint; add waypoints that go round",
            )
    return tuple(points)


def _dist(p: tuple[float, float], q: tuple[float, float]) -> float:
    dx, dy = q[0] - p[0], q[1] - p[1]
    return math.sqrt(dx * dx + dy * dy)


def _short(name: str, where: str) -> str:
    return name.removeprefix(f"{where} points, ")
