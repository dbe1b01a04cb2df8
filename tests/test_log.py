"""The rerun log: what a saved .rrd holds, read back, against the record it came from.

Scalars are stored as float64 and compared exactly; rerun stores positions, strips, arrows and
transforms as float32, so those are compared to float32.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest

from mlpfac import log
from mlpfac.exceptions import ConfigError
from mlpfac.log import compare, sinks
from mlpfac.loop.metrics import metrics

WEIGHT_LAYERS = {"NN_f/output": (0, 54), "NN_f/hidden": (54, 162), "NN_G/output": (162, 168), "NN_G/hidden": (168, 171)}
POSE_ENTITIES = ("/world/robot", "/world/reference_now", "/top/plane/robot", "/top/plane/reference_now")


def per_row(values: pa.Array, instances: int = 1) -> np.ndarray:
    """A list array with exactly ``instances`` per row, as numpy: (rows,), (rows, instances) or (rows, width)."""
    assert pc.all(pc.equal(pc.list_value_length(values), instances)).as_py(), f"a row holds other than {instances}"
    flat = values.flatten()
    if pa.types.is_fixed_size_list(flat.type):
        return flat.flatten().to_numpy(zero_copy_only=False).reshape(len(values), flat.type.list_size)
    flat = flat.to_numpy(zero_copy_only=False)
    return flat if instances == 1 else flat.reshape(len(values), instances)


def expected_series(rec) -> dict[str, np.ndarray]:
    """Every per-step scalar entity and the record's own values for it, written out by hand."""
    n, p, c = rec.n, rec.plant, rec.ctrl
    out = {f"/errors/e{j + 1}": rec.e_true[:n, j] for j in range(3)}
    out["/errors/position"] = np.hypot(rec.e_true[:n, 0], rec.e_true[:n, 1])
    for j, q in enumerate(("v", "omega")):
        out[f"/controls/{q}/cmd"] = rec.u[:n, j]
        out[f"/controls/{q}/meas"] = p["u_meas"][:n, j]
        out[f"/controls/{q}/ref"] = rec.ref[:n, 3 + j]
    for j, side in enumerate(("left", "right")):
        out[f"/wheels/{side}/cmd"] = p["wheel_cmd"][:n, j]
        out[f"/wheels/{side}/meas"] = p["wheel_meas"][:n, j]
    for group, (lo, hi) in WEIGHT_LAYERS.items():  # one entity per layer, one line per weight
        out[f"/weights/{group}"] = c["z"][:n, lo:hi]
    out["/ekf/trace_P"] = c["trace_P"][:n]
    out["/ekf/mean_diag_P"] = c["mean_diag_P"][:n]
    for j in range(3):
        out[f"/ekf/innovation/e{j + 1}"] = c["innovation"][:n, j]
    for j, h in enumerate(("h1", "h2", "h5")):
        out[f"/h/{h}/estimate"] = c["h_hat"][:n, j]
        out[f"/h/{h}/true"] = p["h_true"][:n, j]
    return out


def pose_rows(n: int, stride: int) -> np.ndarray:
    """Steps that carry a pose-rate entity: every ``stride``-th, and the last one."""
    return np.union1d(np.arange(0, n, stride), [n - 1])


def check_contents(rec, ents, geometry) -> None:
    n = rec.n
    steps = np.arange(n)
    series = expected_series(rec)
    assert sum(series[f"/weights/{g}"].shape[1] for g in WEIGHT_LAYERS) == rec.ctrl["z"].shape[1] == 171
    for path, want in series.items():
        col = ents[path].temporal["Scalars:scalars"]
        np.testing.assert_array_equal(col.times["step"], steps, err_msg=path)
        np.testing.assert_array_equal(col.times["sim_time"], np.round(rec.t[:n] * 1e9).astype(np.int64), err_msg=path)
        lines = 1 if want.ndim == 1 else want.shape[1]
        np.testing.assert_array_equal(per_row(col.values, lines), want, err_msg=path)
    assert {p for p in ents if p.startswith("/weights/")} == {p for p in series if p.startswith("/weights/")}
    names = [ents[f"/weights/{g}"].static["SeriesLines:names"].to_pylist()[0] for g in WEIGHT_LAYERS]
    assert [f"NN_f/output/{x}" for x in names[0]] + [f"NN_f/hidden/{x}" for x in names[1]] == rec.labels["z"][:162]
    assert per_row(ents["/errors/e1"].static["SeriesLines:names"]).tolist() == ["e1"]

    # Pose-rate entities: every 5th step and the last, float32.
    rows = pose_rows(n, log.POSE_STRIDE)
    f32 = np.float32
    for path in POSE_ENTITIES:
        for col in ents[path].temporal.values():
            np.testing.assert_array_equal(col.times["step"], rows, err_msg=path)
    pose, ref = rec.pose[rows], rec.ref[rows]
    robot = ents["/world/robot"].temporal
    np.testing.assert_array_equal(per_row(robot["Transform3D:translation"].values)[:, :2], pose[:, :2].astype(f32))
    quat = per_row(robot["Transform3D:quaternion"].values)  # (x, y, z, w) about z
    heading_diff = np.angle(np.exp(1j * (2 * np.arctan2(quat[:, 2], quat[:, 3]) - pose[:, 2])))
    np.testing.assert_allclose(heading_diff, 0.0, atol=1e-6)
    np.testing.assert_array_equal(
        per_row(ents["/top/plane/robot"].temporal["Arrows2D:origins"].values), pose[:, :2].astype(f32)
    )
    np.testing.assert_array_equal(
        per_row(ents["/world/reference_now"].temporal["Arrows3D:origins"].values)[:, :2], ref[:, :2].astype(f32)
    )
    np.testing.assert_array_equal(
        per_row(ents["/top/plane/reference_now"].temporal["Points2D:positions"].values), ref[:, :2].astype(f32)
    )

    # The driven path: a growing strip every 25th step and at the last; the last one is the whole path.
    path_rows = pose_rows(n, log.PATH_STRIDE)
    for ent, dims in (("/world/path", 3), ("/top/plane/path", 2)):
        col = ents[ent].temporal[f"LineStrips{dims}D:strips"]
        np.testing.assert_array_equal(col.times["step"], path_rows, err_msg=ent)
        strips = col.values.to_pylist()
        assert all(len(row) == 1 for row in strips)
        last = np.array(strips[-1][0])[:, :2]
        want = np.vstack([rec.pose[: n : log.PATH_POINT_STRIDE, :2], rec.pose[n - 1, :2]])
        want = want if (n - 1) % log.PATH_POINT_STRIDE else want[:-1]
        np.testing.assert_array_equal(last, want.astype(f32), err_msg=ent)

    # Static scene: reference path, floor, robot shapes, view coordinates, top-view mirror.
    ref_xy = rec.ref[:, :2].astype(f32)
    for ent, comp in (
        ("/world/reference_path", "LineStrips3D:strips"),
        ("/top/plane/reference_path", "LineStrips2D:strips"),
    ):
        strip = np.array(ents[ent].static[comp].to_pylist()[0][0])
        np.testing.assert_array_equal(strip[:, :2], ref_xy, err_msg=ent)
    assert "Boxes3D:half_sizes" in ents["/world/floor"].static
    assert "ViewCoordinates:xyz" in ents["/world"].static
    assert ents["/top/plane"].static["Transform3D:scale"].to_pylist() == [[[1.0, -1.0, 1.0]]]
    chassis, wheel, caster = (ents[f"/world/robot/{g}"].static for g in ("chassis", "left_wheel", "caster"))
    np.testing.assert_allclose(chassis["Boxes3D:half_sizes"].to_pylist()[0][0], geometry[0]["size"], rtol=1e-6)
    np.testing.assert_allclose(chassis["Boxes3D:centers"].to_pylist()[0][0], geometry[0]["pos"], rtol=1e-6)
    assert wheel["Cylinders3D:lengths"].to_pylist()[0][0] == pytest.approx(2 * geometry[1]["size"][1])
    assert wheel["Cylinders3D:radii"].to_pylist()[0][0] == pytest.approx(geometry[1]["size"][0])
    assert caster["Ellipsoids3D:half_sizes"].to_pylist()[0][0] == pytest.approx([geometry[3]["size"][0]] * 3)

    # Events at their step, with their text; the status at the last step.
    if rec.events:
        ev = ents["/events"].temporal["TextLog:text"]
        assert ev.values.to_pylist() == [[e["text"]] for e in rec.events]
        np.testing.assert_array_equal(ev.times["step"], [round(e["time"] / rec.T) for e in rec.events])
    else:
        assert "/events" not in ents
    status = ents["/status"].temporal
    assert status["TextLog:text"].values.to_pylist()[0][0].startswith(metrics(rec)["outcome"])  # metrics.json's word
    assert status["TextLog:text"].times["step"].tolist() == [n - 1]
    assert status["TextLog:level"].values.to_pylist() == [[log.STATUS_LEVEL[rec.status]]]


def test_saved_file_holds_every_entity_equal_to_the_record(record, tmp_path, save_rrd, rrd_contents, robot_geometry):
    from rerun.chunk import RrdReader

    path = tmp_path / "run.rrd"
    save_rrd(record, path)
    ents = rrd_contents(path)
    check_contents(record, ents, robot_geometry)
    assert ents["/__properties"].static["RecordingInfo:name"].to_pylist() == [["synthetic / adaptive / seed 3"]]
    assert ents["/__properties/run"].static["seed"].to_pylist() == [[3]]
    reader = RrdReader(path)
    (rec_store,) = reader.recordings()
    assert (rec_store.application_id, rec_store.recording_id) == ("mlpfac", "synthetic-adaptive-3")
    assert len(reader.blueprints()) == 1  # the default layout travels with the file
    # Nothing but sim_time and step: no wall clock, no log tick.
    assert {tl for e in ents.values() for c in e.temporal.values() for tl in c.times} == {"sim_time", "step"}


def test_diverged_record_logs_only_its_rows(make_record, tmp_path, save_rrd, rrd_contents, robot_geometry):
    rec = make_record(n=1503, status="diverged")  # after the 12.5 s event, before the 20 s one
    path = tmp_path / "run.rrd"
    save_rrd(rec, path)
    ents = rrd_contents(path)
    check_contents(rec, ents, robot_geometry)  # n rows everywhere, last pose row 1502, one event
    assert len(rec.events) == 1
    text = ents["/status"].temporal["TextLog:text"].values.to_pylist()[0][0]
    assert text.startswith("diverged (position error beyond 5 m") and "1503 steps" in text


def test_same_record_gives_the_same_contents(record, tmp_path, save_rrd, rrd_contents):
    """Decoded contents are identical, whatever the flush pattern. The bytes are not: rerun stamps
    chunk and row ids from the clock, and there is no switch for that in 0.41."""
    a = tmp_path / "a.rrd"
    save_rrd(record, a, flush_every=250)
    for flush_every in (1000, record.n + 1):  # the last: only the end's flush, as a recording written after its run
        b = tmp_path / f"b{flush_every}.rrd"
        save_rrd(record, b, flush_every=flush_every)
        _same_contents(rrd_contents(a), rrd_contents(b))


def _same_contents(ea: dict, eb: dict) -> None:
    assert ea.keys() == eb.keys()
    for path in ea:
        assert ea[path].static.keys() == eb[path].static.keys(), path
        for comp, arr in ea[path].static.items():
            assert arr.equals(eb[path].static[comp]), (path, comp)
        assert ea[path].temporal.keys() == eb[path].temporal.keys(), path
        for comp, col in ea[path].temporal.items():
            other = eb[path].temporal[comp]
            assert col.times.keys() == other.times.keys()
            for tl in col.times:
                np.testing.assert_array_equal(col.times[tl], other.times[tl])
            assert col.values.equals(other.values), (path, comp)


def test_non_finite_last_pose_is_left_out_of_the_pictures(make_record, tmp_path, save_rrd, rrd_contents):
    rec = make_record(n=1001, status="diverged")
    rec.pose[1000] = np.nan  # the runner records the step that diverged
    rec.e_true[1000] = np.inf
    save_rrd(rec, tmp_path / "run.rrd")
    ents = rrd_contents(tmp_path / "run.rrd")
    assert ents["/world/robot"].temporal["Transform3D:translation"].times["step"][-1] == 995
    assert ents["/world/path"].temporal["LineStrips3D:strips"].times["step"][-1] == 1000  # up to 995, no NaN
    last_strip = np.array(ents["/world/path"].temporal["LineStrips3D:strips"].values.to_pylist()[-1][0])
    assert np.isfinite(last_strip).all() and len(last_strip) == 1000 // log.PATH_POINT_STRIDE
    e1 = per_row(ents["/errors/e1"].temporal["Scalars:scalars"].values)
    assert len(e1) == 1001 and np.isinf(e1[-1])


def test_run_stopped_at_the_first_step(make_record, tmp_path, save_rrd, rrd_contents, robot_geometry):
    rec = make_record(n=1, status="diverged")
    path = tmp_path / "run.rrd"
    save_rrd(rec, path)
    check_contents(rec, rrd_contents(path), robot_geometry)


def test_end_twice_and_flush_past_n(make_record, tmp_path, rrd_contents):
    rec = make_record(n=300, status="interrupted")
    sink = log.make_sink(save=tmp_path / "run.rrd")
    sink.begin(rec)
    sink.flush(rec, upto=2500)  # beyond n: only what the record holds
    sink.end(rec)
    sink.end(rec)
    ents = rrd_contents(tmp_path / "run.rrd")
    assert len(ents["/errors/e1"].temporal["Scalars:scalars"].values) == 300
    assert ents["/status"].temporal["TextLog:level"].values.to_pylist() == [["WARN"]]


def test_a_real_run_through_the_runner(tmp_path, rrd_contents):
    from mlpfac.loop.runner import run
    from mlpfac.scenario.parse import load

    scn = load("paper").with_overrides(duration=3.0)
    rec = run(scn, sink=log.make_sink(save=tmp_path / "run.rrd", recording_id="real"))
    ents = rrd_contents(tmp_path / "run.rrd")
    assert rec.n > 0
    for path in ("/errors/e1", "/controls/v/cmd", "/ekf/trace_P", "/h/h1/true"):
        col = ents[path].temporal["Scalars:scalars"]
        np.testing.assert_array_equal(col.times["step"], np.arange(rec.n), err_msg=path)
    weights = sorted(p for p in ents if p.startswith("/weights/"))
    assert weights == sorted(f"/weights/{g}" for g in WEIGHT_LAYERS)
    col = ents["/weights/NN_f/output"].temporal["Scalars:scalars"]
    np.testing.assert_array_equal(per_row(col.values, 54), rec.ctrl["z"][: rec.n, :54])


def test_robot_rests_on_the_floor(make_record, tmp_path, save_rrd, rrd_contents):
    """Shapes given relative to a frame at axle height (as the MuJoCo plant does) are lifted."""
    wheel = {"type": "cylinder", "size": [0.05, 0.0125], "quat": [0.7071068, -0.7071068, 0, 0]}
    geometry = [
        {"name": "chassis", "type": "box", "size": [0.15, 0.1, 0.04], "pos": [-0.05, 0.0, 0.03]},
        {"name": "caster", "type": "sphere", "size": [0.02], "pos": [-0.17, 0.0, -0.03]},
        {"name": "left_wheel", "pos": [0.0, 0.14, 0.0], **wheel},
        {"name": "right_wheel", "pos": [0.0, -0.14, 0.0], **wheel},
    ]
    save_rrd(make_record(N=50), tmp_path / "run.rrd", geometry=geometry)
    ents = rrd_contents(tmp_path / "run.rrd")
    z = {g: ents[f"/world/robot/{g}"].static for g in ("chassis", "caster", "left_wheel")}
    assert z["left_wheel"]["Cylinders3D:centers"].to_pylist()[0][0][2] == pytest.approx(0.05, abs=1e-6)
    assert z["caster"]["Ellipsoids3D:centers"].to_pylist()[0][0][2] == pytest.approx(0.02, abs=1e-6)
    assert z["chassis"]["Boxes3D:centers"].to_pylist()[0][0][2] == pytest.approx(0.08, abs=1e-6)


def test_series_names_fall_back_to_indices(make_record):
    rec = make_record(N=20)
    rec.labels = {}
    series = {s.path: s for s in log.plan_series(rec)}
    assert series["weights"].names == [f"w{i}" for i in range(171)]
    paths = list(series)
    assert "h/h1/estimate" in paths and "ekf/innovation/e3" in paths
    rec.plant["slip"] = np.zeros((20, 2))  # telemetry the log does not know still gets logged
    assert {"plant/slip/0", "plant/slip/1"} <= {s.path for s in log.plan_series(rec)}


def test_no_output_asked_gives_no_sink():
    assert log.make_sink() is None


def test_unwritable_save_path(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for bad in (blocker / "run.rrd", tmp_path):  # under a file; a folder
        with pytest.raises(ConfigError) as err:
            log.make_sink(save=bad)
        assert err.value.where == str(bad) and "\n" not in str(err.value)


def test_unreachable_viewer(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, not listening: nobody answers
        with pytest.raises(ConfigError, match="no rerun viewer is listening"):
            log.make_sink(connect=f"rerun+http://127.0.0.1:{port}/proxy")
    with pytest.raises(ConfigError, match="rerun\\+http://127.0.0.1:9876/proxy"):
        log.make_sink(connect="http://127.0.0.1:9876")


def test_no_display_for_spawn_or_view(tmp_path, monkeypatch):
    for var in ("DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(sinks, "SPAWN_PORT", _closed_port())
    with pytest.raises(ConfigError, match="no display"):
        log.make_sink(spawn=True)
    (tmp_path / "run.rrd").write_bytes(b"")
    with pytest.raises(ConfigError, match="no display"):
        compare.view([tmp_path])


def test_view_needs_a_run_in_each_folder(tmp_path):
    (tmp_path / "good").mkdir()
    (tmp_path / "good" / "run.rrd").write_bytes(b"")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError) as err:
        compare.view([tmp_path / "good", tmp_path / "empty"])
    assert err.value.where == str(tmp_path / "empty")
    assert err.value.what == "no run.rrd in this folder"


def test_runs_without_logging_do_not_import_rerun():
    code = "import sys, mlpfac.loop.runner, mlpfac.cli, mlpfac.scenario.parse, mlpfac.io.files; print('rerun' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=Path(__file__).parents[1]
    )
    assert out.stdout.strip() == "False"


def _closed_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_recording_check_finds_a_file_cut_short(record, tmp_path, save_rrd):
    path = tmp_path / "run.rrd"
    save_rrd(record, path)
    sinks.check_recording(path)  # whole: passes
    data = path.read_bytes()
    for cut in (len(data) - 12, len(data) // 2, 100):  # before the footer, mid-message, in the header
        (tmp_path / "cut.rrd").write_bytes(data[:cut])
        with pytest.raises(ConfigError, match="cut short") as err:
            sinks.check_recording(tmp_path / "cut.rrd", shown="shown/run.rrd")
        assert err.value.where == "shown/run.rrd"


def test_moved_names_still_reach_log():
    assert log.make_sink is sinks.make_sink and log.view is compare.view


@pytest.mark.parametrize("scenario", ["paper", "eight-nominal"])  # the kinematic plant, the MuJoCo robot
@pytest.mark.parametrize("controller", ["adaptive", "adaptive-best", "corradini", "kanayama"])
def test_schema_covers_every_key_of_a_real_run(scenario, controller):
    """Every array a real run records has a row in the log's schema (a new telemetry key needs one),
    no two series share an entity, and every series shows in a view of the default layout."""
    from dataclasses import fields

    from mlpfac.log.layout import VIEWS
    from mlpfac.log.schema import rows_for
    from mlpfac.loop.runner import run
    from mlpfac.scenario.parse import load

    rec = run(load(scenario).with_overrides(controller=controller, duration=0.05))
    arrays = [f.name for f in fields(rec) if isinstance(getattr(rec, f.name), np.ndarray)]
    keys = [("record", a) for a in arrays] + [(s, k) for s in ("plant", "ctrl") for k in getattr(rec, s)]
    assert ("plant", "u_meas") in keys and len(keys) > len(arrays) + 1
    assert [k for k in keys if not rows_for(*k)] == []
    paths = [s.path for s in log.plan_series(rec)]
    assert len(paths) == len(set(paths))
    origins = [origin[1:] for _, _, origin, _ in VIEWS]
    assert [p for p in paths if not any(p == o or p.startswith(o + "/") for o in origins)] == []


def test_schema_rows_are_well_formed():
    from mlpfac.log import schema

    for row in schema.SCHEMA:
        assert row.store in ("record", "plant", "ctrl") and row.send in (
            schema.LINES,
            schema.LAYERS,
            schema.CHANGE,
            schema.SCENE,
            schema.UNSENT,
        ), row
        assert bool(row.path) == (row.send != schema.UNSENT), row
        assert row.names == () or len(row.names) == len(row.cols or row.names), row
        assert ("{name}" in row.path) == bool(row.names) or row.send != schema.LINES, row


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """The synthetic record (events at 12.5 s and 20 s) logged as the runner does, read back."""
    from conftest import log_record, read_rrd, synthetic_record

    rec = synthetic_record()
    path = tmp_path_factory.mktemp("logged") / "run.rrd"
    log_record(rec, path)
    return rec, read_rrd(path), path


def test_events_are_marked_on_every_time_plot_and_the_text_panel_says_where_to_look(logged):
    """A diamond at each event on the first series of every marked view, at that series' value; the
    text panel names the scenario, the controller, the events and the run's figures."""
    from mlpfac.log.layout import marked_origins

    record, ents, path = logged
    steps = [int(round(ev["time"] / record.T)) for ev in record.events]
    origins = marked_origins(list(ents))
    assert {"/errors/e1", "/errors/e3", "/wheels", "/weight_change", "/ekf/log10_trace_P"} <= set(origins)
    for origin in origins:
        col = ents[f"{origin}/event"].temporal["Scalars:scalars"]
        assert col.times["step"].tolist() == steps, origin
    e1 = [v[0] for v in ents["/errors/e1/event"].temporal["Scalars:scalars"].values.to_pylist()]
    assert e1 == pytest.approx(record.e_true[steps, 0].tolist())
    # Written at the start and again at the end (static: the later write is what the viewer shows).
    texts = [t[0] for t in about_texts(path)]
    assert len(texts) == 2
    (text,) = [t for t in texts if "position RMS" in t]
    assert "**synthetic**" in text and "`adaptive`" in text and "event at 12.5 s" in text and "event at 20 s" in text


def about_texts(path) -> list[list[str]]:
    from rerun.chunk import RrdReader

    chunks = [c for c in RrdReader(path).store().stream().to_chunks() if str(c.entity_path) == "/about"]
    return [t for c in chunks for t in c.to_record_batch().column("TextDocument:text").to_pylist()]


def test_weights_show_as_their_change_per_layer(logged):
    from mlpfac.control.adaptive.networks import Networks

    labels = Networks().labels()
    idx = [i for i, name in enumerate(labels) if name.startswith("NN_G/hidden/")]
    record, ents, _ = logged
    col = ents["/weight_change/NN_G/hidden"].temporal["Scalars:scalars"]
    z = record.ctrl["z"]
    k = col.times["step"][100]
    want = np.sqrt(np.mean((z[k, idx] - z[0, idx]) ** 2))
    assert col.values.to_pylist()[100][0] == pytest.approx(want)


def test_runs_compared_in_one_recording_take_their_controllers_colours(tmp_path, make_record, save_rrd):
    """`mlpfac view A B --save`: each run under runs/<controller>-s<seed>/, its lines recoloured, one layout."""
    from conftest import read_rrd

    from mlpfac.cli import main
    from mlpfac.loop.metrics import metrics
    from mlpfac.plots import controller_colors

    for ctrl, seed in (("adaptive", 3), ("kanayama", 4)):
        rec = make_record(N=600, seed=seed)
        rec.controller = ctrl
        save_rrd(rec, tmp_path / ctrl / "run.rrd")
        (tmp_path / ctrl / "metrics.json").write_text(json.dumps(metrics(rec)))
    out = tmp_path / "both.rrd"
    assert main(["view", str(tmp_path / "adaptive"), str(tmp_path / "kanayama"), "--save", str(out)]) == 0
    ents = read_rrd(out)
    for label in ("adaptive-s3", "kanayama-s4"):
        assert f"/runs/{label}/errors/e1" in ents and f"/runs/{label}/top/plane/path" in ents
    r, g, b = controller_colors(["kanayama"])["kanayama"]
    colors = ents["/runs/kanayama-s4/errors/e1"].static["SeriesLines:colors"].to_pylist()[0]
    assert colors == [(r << 24) | (g << 16) | (b << 8) | 255]
    assert "kanayama-s4** (green)" in about_texts(out)[0][0]
    assert main(["view", str(tmp_path / "adaptive"), str(tmp_path / "kanayama"), "--save", str(tmp_path)]) == 2


def test_a_recording_that_cannot_be_closed_is_an_error_not_a_hang(monkeypatch):
    """rerun's disconnect never returns when its file cannot be written (seen on a full disk): the
    sink gives up after CLOSE_TIMEOUT_S with an OSError, so the run fails instead of hanging."""
    import threading

    from mlpfac.log import recorder

    class Stuck:
        def __init__(self) -> None:
            self.release = threading.Event()

        def disconnect(self) -> None:
            self.release.wait()

    stuck = Stuck()
    sink = recorder.RerunSink(stuck, "stuck", serving=False, viewer_url=None)
    monkeypatch.setattr(recorder, "CLOSE_TIMEOUT_S", 0.2)
    try:
        with pytest.raises(OSError, match="could not be closed within 0.2 s"):
            sink.close()
    finally:
        stuck.release.set()
