"""Mesh geoms of a robot (``plant.geometry()`` shapes of type "mesh") as rerun meshes.

A shape carries its mesh as plain arrays (``vertices`` (V, 3) in the geom's frame, ``faces``
(F, 3)), read from the compiled model by the plant; here each is posed in the robot's frame once
and sent static, under the robot's entity whose transform follows the pose every step.
"""

from __future__ import annotations

import numpy as np
import rerun as rr


def _rotation(quat) -> np.ndarray:
    w, x, y, z = np.asarray(quat, dtype=float) / np.linalg.norm(quat)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def posed_vertices(g: dict, lift: float = 0.0) -> np.ndarray:
    """(V, 3) vertices of a mesh shape in the robot's frame, raised by ``lift``."""
    v = np.asarray(g["vertices"], dtype=float) @ _rotation(g.get("quat", [1.0, 0.0, 0.0, 0.0])).T
    return v + np.asarray(g.get("pos", [0.0, 0.0, 0.0]), dtype=float) + [0.0, 0.0, lift]


def lowest_point(g: dict) -> float:
    """Height of a mesh shape's lowest vertex in the robot's frame."""
    return float(posed_vertices(g)[:, 2].min()) if len(g["vertices"]) else np.inf


def mesh_archetype(g: dict, lift: float, color: tuple[int, ...]) -> rr.Mesh3D:
    """A mesh shape as an ``rr.Mesh3D`` with smooth vertex normals, in one colour."""
    v = posed_vertices(g, lift)
    faces = np.asarray(g["faces"], dtype=np.int32)
    n = np.zeros_like(v)
    face_n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    for k in range(3):
        np.add.at(n, faces[:, k], face_n)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return rr.Mesh3D(
        vertex_positions=v.astype(np.float32),
        triangle_indices=faces,
        vertex_normals=n.astype(np.float32),
        albedo_factor=color,
    )
