"""The pictures: the world in 3D (floor, robot shapes, reference path) and its top view, sent once,
and the robot's pose, the reference pose and the driven path over time.

The robot's pose, the reference arrow and the top-view markers are sent every ``POSE_STRIDE``
steps, the driven path every ``PATH_STRIDE`` steps (a growing line strip through every
``PATH_POINT_STRIDE``-th pose); the sink adds the last valid row, so the final picture is exact.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import rerun as rr

from mlpfac.log import meshes
from mlpfac.log.schema import PATH_COLOR, REF_COLOR, ROBOT_COLOR, entity_part
from mlpfac.log.series import time_index
from mlpfac.log.terrain import robot_pose, send_forces, tilts
from mlpfac.loop.record import RunRecord

POSE_STRIDE = 5  # robot transform, reference arrow, top-view markers: every 5th step
PATH_STRIDE = 25  # the driven path is re-sent every 25th step ...
PATH_POINT_STRIDE = 5  # ... through every 5th pose


def send_static_scene(rec: rr.RecordingStream, ref_xy: np.ndarray, geometry: Sequence[dict]) -> None:
    """Floor, reference path, robot shapes, and the styles of the entities :func:`send_poses` fills."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    lo, hi = bounds(ref_xy)
    center, half = (lo + hi) / 2, (hi - lo) / 2 + 1.0
    rec.log(
        "world/floor",
        rr.Boxes3D(
            half_sizes=[[half[0], half[1], 0.005]],
            centers=[[center[0], center[1], -0.006]],
            colors=[(70, 70, 75)],
            fill_mode="solid",
        ),
        static=True,
    )
    if len(ref_xy):
        rec.log(
            "world/reference_path",
            rr.LineStrips3D([np.c_[ref_xy, np.full(len(ref_xy), 0.002)]], colors=[REF_COLOR], radii=[0.02]),
            static=True,
        )
    for name, arch in robot_shapes(geometry):
        rec.log(f"world/robot/{name}", arch, static=True)
    rec.log("world/robot", rr.TransformAxes3D(axis_length=0.15), static=True)
    rec.log("world/reference_now", rr.Arrows3D.from_fields(colors=[REF_COLOR], radii=[0.012]), static=True)
    rec.log("world/path", rr.LineStrips3D.from_fields(colors=[PATH_COLOR], radii=[0.01]), static=True)
    # The top view: a 2D view draws y downwards, so the plane is mirrored once, here, and the
    # entities below it keep the record's own (x, y).
    rec.log("top/plane", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
    if len(ref_xy):
        rec.log("top/plane/reference_path", rr.LineStrips2D([ref_xy], colors=[REF_COLOR], radii=[0.03]), static=True)
    rec.log(
        "top/plane/axes",
        rr.Arrows2D(
            origins=[[0.0, 0.0], [0.0, 0.0]],
            vectors=[[0.3, 0.0], [0.0, 0.3]],
            colors=[(230, 70, 70), (80, 200, 90)],
            labels=["x", "y"],
            radii=[0.01],
        ),
        static=True,
    )
    rec.log("top/plane/path", rr.LineStrips2D.from_fields(colors=[PATH_COLOR], radii=[0.012]), static=True)
    rec.log("top/plane/robot", rr.Arrows2D.from_fields(colors=[ROBOT_COLOR], radii=[0.04]), static=True)
    rec.log("top/plane/reference_now", rr.Points2D.from_fields(colors=[REF_COLOR], radii=[0.05]), static=True)


def send_poses(rec: rr.RecordingStream, record: RunRecord, rows: np.ndarray, path_rows: np.ndarray) -> None:
    """Robot, reference arrow and top-view markers at ``rows``; the driven path at ``path_rows``.
    A non-finite pose (the step a run diverged at) is left out of the pictures."""
    rows = rows[np.all(np.isfinite(record.pose[rows, :3]), axis=1) & np.all(np.isfinite(record.ref[rows, :3]), axis=1)]
    if len(rows):
        x, y, th = record.pose[rows].T
        zeros = np.zeros_like(x)
        idx = time_index(record, rows)
        if record.world or tilts(record):  # on the ground under it, in the floor's tilted frame (mlpfac.log.terrain)
            translation, quaternion = robot_pose(record, rows)
        else:
            translation, quaternion = np.c_[x, y, zeros], np.c_[zeros, zeros, np.sin(th / 2), np.cos(th / 2)]
        rec.send_columns(
            "world/robot",
            indexes=idx,
            columns=rr.Transform3D.columns(translation=translation, quaternion=quaternion),
        )
        send_forces(rec, record, rows, idx)
        r = record.ref[rows]
        heading = 0.3 * np.c_[np.cos(r[:, 2]), np.sin(r[:, 2])]
        rec.send_columns(
            "world/reference_now",
            indexes=idx,
            columns=rr.Arrows3D.columns(origins=np.c_[r[:, :2], zeros + 0.02], vectors=np.c_[heading, zeros]),
        )
        rec.send_columns(
            "top/plane/robot",
            indexes=idx,
            columns=rr.Arrows2D.columns(origins=np.c_[x, y], vectors=0.45 * np.c_[np.cos(th), np.sin(th)]),
        )
        rec.send_columns("top/plane/reference_now", indexes=idx, columns=rr.Points2D.columns(positions=r[:, :2]))
    if len(path_rows):
        strips = [driven_path(record.pose, k) for k in path_rows]
        idx = time_index(record, path_rows)
        rec.send_columns(
            "world/path",
            indexes=idx,
            columns=rr.LineStrips3D.columns(strips=[np.c_[p, np.full(len(p), 0.004)] for p in strips]),
        )
        rec.send_columns("top/plane/path", indexes=idx, columns=rr.LineStrips2D.columns(strips=strips))


def driven_path(pose: np.ndarray, k: int) -> np.ndarray:
    """(x, y) of every ``PATH_POINT_STRIDE``-th pose up to step k, and of step k itself: (m, 2)."""
    xy = pose[: k + 1 : PATH_POINT_STRIDE, :2]
    xy = xy if k % PATH_POINT_STRIDE == 0 else np.vstack([xy, pose[k, :2]])
    return xy[np.all(np.isfinite(xy), axis=1)]


def strided(a: int, b: int, stride: int) -> np.ndarray:
    """The steps k in [a, b) with k % stride == 0."""
    return np.arange(-(-a // stride) * stride, b, stride)


def bounds(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of the finite points of ``xy`` ((-1, -1), (1, 1) without any)."""
    xy = xy[np.all(np.isfinite(xy), axis=1)] if len(xy) else xy
    if not len(xy):
        return np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    return xy.min(axis=0), xy.max(axis=0)


def robot_shapes(geometry: Sequence[dict]) -> list[tuple[str, object]]:
    """rerun archetypes for plant.geometry() shapes (MuJoCo sizes: half sizes, radius, half length).

    The shapes are given relative to the measured frame, whose height differs between plants (the
    floor, the axle): they are lifted together so that the lowest point touches the floor.
    """
    out: list[tuple[str, object]] = []
    seen: set[str] = set()
    lift = -min((_lowest_point(g) for g in geometry), default=0.0)
    for i, g in enumerate(geometry):
        name = entity_part(str(g.get("name") or f"geom{i}"))
        if name in seen:
            name = f"{name}_{i}"
        seen.add(name)
        size = np.asarray(g.get("size", [0.05]), dtype=float)
        pos = [np.asarray(g.get("pos", [0.0, 0.0, 0.0]), dtype=float) + [0.0, 0.0, lift]]
        w, x, y, z = np.asarray(g.get("quat", [1.0, 0.0, 0.0, 0.0]), dtype=float)
        quat = [rr.Quaternion(xyzw=[x, y, z, w])]
        rgba = np.asarray(g.get("rgba", [0.7, 0.7, 0.7, 1.0]), dtype=float)
        color = [tuple(int(round(255 * c)) for c in np.clip(rgba, 0.0, 1.0))]
        kind = g.get("type")
        if kind == "box":
            arch = rr.Boxes3D(half_sizes=[size[:3]], centers=pos, quaternions=quat, colors=color, fill_mode="solid")
        elif kind == "cylinder":
            arch = rr.Cylinders3D(
                lengths=[2 * size[1]], radii=[size[0]], centers=pos, quaternions=quat, colors=color, fill_mode="solid"
            )
        elif kind == "capsule":
            arch = rr.Capsules3D(
                lengths=[2 * size[1]], radii=[size[0]], translations=pos, quaternions=quat, colors=color
            )
        elif kind == "sphere":
            arch = rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], centers=pos, colors=color, fill_mode="solid")
        elif kind == "mesh":
            arch = meshes.mesh_archetype(g, lift, color[0])
        else:
            arch = rr.TextLog(f"geom {name!r}: type {kind!r} is not drawn", level="WARN")
        out.append((name, arch))
    return out


def _lowest_point(g: dict) -> float:
    """Height of a shape's lowest point in its frame (boxes, cylinders, capsules, spheres)."""
    size = np.asarray(g.get("size", [0.05]), dtype=float)
    w, x, y, z = np.asarray(g.get("quat", [1.0, 0.0, 0.0, 0.0]), dtype=float)
    up = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])  # row z of R(quat)
    kind = g.get("type")
    if kind == "box":
        extent = float(np.abs(up) @ size[:3])
    elif kind in ("cylinder", "capsule"):  # axis along the shape's z; a capsule adds its end caps
        r, h, c = size[0], size[1], abs(up[2])
        extent = c * h + (r if kind == "capsule" else r * np.sqrt(max(0.0, 1.0 - c * c)))
    elif kind == "sphere":
        extent = float(size[0])
    elif kind == "mesh":
        return meshes.lowest_point(g)
    else:
        return np.inf
    return float(g.get("pos", [0.0, 0.0, 0.0])[2]) - extent
