"""Shared by the tests: the ``menagerie`` marker (a test that needs a MuJoCo Menagerie robot skips,
saying why, where the robot is neither local nor downloadable), and for the logging tests
(test_log.py, test_viewer_browser.py) a deterministic synthetic run record, logging it the way the
runner does, and reading an .rrd back."""

from __future__ import annotations

import functools
import signal
import threading
from dataclasses import dataclass, field

import numpy as np
import pytest

from mlpfac.control.adaptive.networks import Networks
from mlpfac.loop.record import RunRecord
from mlpfac.model import h_true, tracking_error
from mlpfac.scenario.reference import Eight, sample

MENAGERIE_ROBOT = "pal_tiago"  # the Menagerie robot of the tiago-* scenarios
PROBE_S = 3.0  # how long the one probe of the download server may take


@functools.cache
def menagerie_missing(robot: str = MENAGERIE_ROBOT) -> str | None:
    """Why the tests cannot have ``robot`` from MuJoCo Menagerie, or None when they can: it is under
    MENAGERIE_ROOT, in mujoco-menagerie's download cache, or its archive answers a HEAD request
    within PROBE_S seconds (once per session; no download starts here)."""
    try:
        import mujoco_menagerie as mm
    except ImportError:
        return "needs mujoco-menagerie (pip install -e '.[test]')"
    cache, r = mm.Cache(), mm.get(robot)
    if cache.root is not None:
        return None if (cache.root / robot).is_dir() else f"MENAGERIE_ROOT={cache.root} has no {robot}/"
    if cache.is_cached(r) or _answers(f"{cache.base_url}/{r.asset}"):
        return None
    return (
        f"needs MuJoCo Menagerie's {robot}: not in MENAGERIE_ROOT (unset), not in the download cache "
        f"{cache.dir}, and {cache.base_url} did not answer within {PROBE_S:g} s (offline?); set "
        "MENAGERIE_ROOT to a Menagerie checkout, or run the tests online once"
    )


def _answers(url: str) -> bool:
    """Whether ``url`` answers a HEAD request within PROBE_S seconds (name lookup included)."""
    import urllib.request

    ok: list[bool] = []

    def probe() -> None:
        try:
            req = urllib.request.Request(url, method="HEAD", headers={"User-Agent": "mujoco-menagerie"})
            with urllib.request.urlopen(req, timeout=PROBE_S):
                ok.append(True)
        except Exception:
            pass

    t = threading.Thread(target=probe, name="menagerie-probe", daemon=True)
    t.start()
    t.join(PROBE_S + 1.0)
    return bool(ok)


@functools.cache
def _menagerie_scenarios() -> frozenset[str]:
    """The shipped scenarios whose robot comes from MuJoCo Menagerie."""
    from mlpfac.scenario.parse import load, scenario_names

    models = {n: getattr(load(n, build=False).plant_config, "model", None) for n in scenario_names()}
    return frozenset(n for n, m in models.items() if isinstance(m, str) and m.startswith("menagerie:"))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test parametrized with a shipped scenario on a Menagerie robot needs that robot too."""
    for item in items:
        spec = getattr(item, "callspec", None)
        if spec is not None and any(isinstance(v, str) and v in _menagerie_scenarios() for v in spec.params.values()):
            item.add_marker(pytest.mark.menagerie)


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("menagerie") is not None and (why := menagerie_missing()) is not None:
        pytest.skip(why)


# A suite started in the background of a non-interactive shell (nohup, `cmd &`) inherits SIGINT
# ignored, and so would every run it starts: the Ctrl-C tests need Python's own handler here, and
# the default in the processes they start (a caught signal is reset to the default by exec).
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

GEOMETRY = [
    {
        "name": "chassis",
        "type": "box",
        "size": [0.15, 0.1, 0.04],
        "pos": [0.05, 0.0, 0.09],
        "quat": [1, 0, 0, 0],
        "rgba": [0.3, 0.5, 0.8, 1],
    },
    {
        "name": "left wheel",
        "type": "cylinder",
        "size": [0.05, 0.015],
        "pos": [0.0, 0.16, 0.05],
        "quat": [0.7071068, 0.7071068, 0, 0],
        "rgba": [0.1, 0.1, 0.1, 1],
    },
    {
        "name": "right wheel",
        "type": "cylinder",
        "size": [0.05, 0.015],
        "pos": [0.0, -0.16, 0.05],
        "quat": [0.7071068, 0.7071068, 0, 0],
        "rgba": [0.1, 0.1, 0.1, 1],
    },
    {
        "name": "caster",
        "type": "sphere",
        "size": [0.02],
        "pos": [0.17, 0.0, 0.02],
        "quat": [1, 0, 0, 0],
        "rgba": [0.6, 0.6, 0.6, 1],
    },
]


def synthetic_record(N: int = 2500, n: int | None = None, seed: int = 3, status: str = "ok") -> RunRecord:
    """A realistic-looking adaptive run on the figure of eight (37), filled without simulating.

    The robot starts 0.3 m off and converges; at 12.5 s (the T -> 1.5 T event) it is knocked off
    again. 171 weights drift as random walks, trace(P) decays, the wheels follow (v, omega).
    Only the first ``n`` rows are filled (default N); the rest stay NaN, as in a diverged run.
    """
    n = N if n is None else n
    T = 0.01
    rng = np.random.default_rng(seed)
    rec = RunRecord.allocate("synthetic", "adaptive", seed, T, N)
    t = rec.t
    ref = sample(Eight(), t)  # (N, 5)
    rec.ref[:] = ref
    bump = 0.3 * np.exp(-t / 1.5) + 0.15 * np.exp(-(t - 12.5) / 1.0) * (t >= 12.5)
    normal = np.c_[-np.sin(ref[:, 2]), np.cos(ref[:, 2])]
    pose = np.c_[ref[:, :2] + bump[:, None] * normal, ref[:, 2] + 0.5 * bump * np.cos(3 * t)]
    e_true = np.array([tracking_error(q, r) for q, r in zip(pose, ref, strict=True)])
    e = e_true + rng.normal(0.0, 1e-3, (N, 3))
    u = np.c_[ref[:, 3] + 2.0 * e_true[:, 0], ref[:, 4] + 3.0 * e_true[:, 1] + 2.0 * np.sin(e_true[:, 2])]
    u_meas = u + rng.normal(0.0, 5e-3, (N, 2))
    r_wheel, half_track = 0.05, 0.16
    wheel_cmd = np.c_[u[:, 0] - half_track * u[:, 1], u[:, 0] + half_track * u[:, 1]] / r_wheel
    alpha = Networks().alpha
    z = np.cumsum(rng.normal(0.0, 0.02, (N, alpha)), axis=0) + rng.normal(0.0, 0.5, alpha)
    trace_P = 5.0 * alpha / (1.0 + t)
    h = np.array([h_true(ei, r[3], r[4], T) for ei, r in zip(e_true, ref, strict=True)])
    rows = slice(0, n)
    rec.pose[rows], rec.pose_meas[rows] = pose[rows], pose[rows] + rng.normal(0, 1e-3, (N, 3))[rows]
    rec.e[rows], rec.e_true[rows], rec.u[rows] = e[rows], e_true[rows], u[rows]
    plant = {
        "u_meas": u_meas,
        "wheel_cmd": wheel_cmd,
        "wheel_meas": wheel_cmd + rng.normal(0.0, 0.05, (N, 2)),
        "h_true": h,
    }
    ctrl = {
        "z": z,
        "trace_P": trace_P,
        "mean_diag_P": trace_P / alpha,
        "innovation": rng.normal(0.0, 1e-3, (N, 3)) * (1 + 5 * np.exp(-t))[:, None],
        "h_hat": h + 0.01 * np.exp(-t / 3)[:, None] * np.cos(np.arange(3) + t[:, None]),
    }
    for store, values in ((rec.plant, plant), (rec.ctrl, ctrl)):
        for key, arr in values.items():
            store[key] = np.full(arr.shape, np.nan)
            store[key][rows] = arr[rows]
    rec.labels = {"z": Networks().labels(), "h_hat": ["h1", "h2", "h5"]}
    rec.events = [
        {
            "time": 12.5,
            "kind": "control_period",
            "params": {"factor": 1.5},
            "text": "control period T_p 0.01 -> 0.015 s",
        },
        {"time": 20.0, "kind": "sensor_delay", "params": {"steps": 2}, "text": "sensor delay 0 -> 2 steps"},
    ]
    rec.events = [ev for ev in rec.events if ev["time"] < n * T]
    rec.n, rec.status = n, status
    rec.reason = "" if status == "ok" else f"position error beyond 5 m at t = {(n - 1) * T:.2f} s"
    return rec


def log_record(rec: RunRecord, path, flush_every: int = 250, geometry: list[dict] = GEOMETRY) -> None:
    """Log ``rec`` to ``path`` the way the runner does: begin, flush every 250 steps, end."""
    from mlpfac import log

    name, rid = f"{rec.scenario} / {rec.controller} / seed {rec.seed}", f"{rec.scenario}-{rec.controller}-{rec.seed}"
    sink = log.make_sink(save=path, recording_name=name, recording_id=rid)
    sink.begin(rec, geometry=geometry, ref_path=rec.ref)
    for k in range(flush_every, rec.n + 1, flush_every):
        sink.flush(rec, upto=k)
    sink.end(rec)


@dataclass
class Column:
    """One component of one entity over time, rows sorted by step."""

    times: dict[str, np.ndarray]  # timeline -> (rows,) int64 (sim_time in ns)
    values: object  # pyarrow list array, one entry per row


@dataclass
class Entity:
    static: dict[str, object] = field(default_factory=dict)  # component -> pyarrow array (last write)
    static_row: dict[str, bytes] = field(default_factory=dict)  # component -> row id of that write
    temporal: dict[str, Column] = field(default_factory=dict)


def read_rrd(path) -> dict[str, Entity]:
    """Every entity of the file's recording: static components and time-sorted temporal columns."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    parts: dict[str, dict[str, list]] = {}
    out: dict[str, Entity] = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        ent = out.setdefault(chunk.entity_path, Entity())
        rb = chunk.to_record_batch()
        names = [f.name for f in rb.schema if f.metadata and f.metadata.get(b"rerun:kind") == b"data"]
        timelines = [f.name for f in rb.schema if f.metadata and f.metadata.get(b"rerun:kind") == b"index"]
        row_id = max(rb.column("rerun.controls.RowId").to_pylist())  # time-ordered: the last write wins
        for name in names:
            if chunk.is_static:
                if row_id >= ent.static_row.get(name, b""):
                    ent.static[name], ent.static_row[name] = rb.column(name), row_id
            else:
                times = {tl: rb.column(tl).cast(pa.int64()).to_numpy() for tl in timelines}
                parts.setdefault(chunk.entity_path, {}).setdefault(name, []).append((times, rb.column(name)))
    for path_, comps in parts.items():
        for name, pieces in comps.items():
            times = {tl: np.concatenate([p[0][tl] for p in pieces]) for tl in pieces[0][0]}
            values = pa.concat_arrays([p[1] for p in pieces])
            order = np.argsort(times.get("step", times.get("sim_time")), kind="stable")
            out[path_].temporal[name] = Column({tl: v[order] for tl, v in times.items()}, values.take(pa.array(order)))
    return out


@pytest.fixture(scope="session")
def record() -> RunRecord:
    """The synthetic 2500-step, 171-weight record (read-only: tests must not change it)."""
    return synthetic_record()


@pytest.fixture
def make_record():
    """``synthetic_record(N=2500, n=None, seed=3, status="ok")``."""
    return synthetic_record


@pytest.fixture
def save_rrd():
    """``log_record(record, path, flush_every=250, geometry=GEOMETRY)``: log as the runner does."""
    return log_record


@pytest.fixture
def rrd_contents():
    """``read_rrd(path) -> {entity path: Entity}``."""
    return read_rrd


@pytest.fixture
def robot_geometry() -> list[dict]:
    return GEOMETRY
