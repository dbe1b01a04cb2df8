"""The robot as the viewer draws it: its visual geoms posed in the pose frame (meshes with their
vertices and triangles), read once by :func:`mlpfac.plants.mjcf.robot.read_robot`."""

from __future__ import annotations

import mujoco
import numpy as np

from mlpfac.model import matmul
from mlpfac.plants.mjcf import edits

SHAPES = {
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    edits.MESH: "mesh",
}
SIZE_LEN = {"box": 3, "cylinder": 2, "sphere": 1, "mesh": 0}


def static_geometry(m: mujoco.MjModel, d: mujoco.MjData, site: int, root: int, visual_only: bool) -> list[dict]:
    """Visual geoms (contype = conaffinity = 0) of the robot, posed relative to the site frame; all
    of its geoms when its model has no visual ones (the tyres added here are never drawn). A mesh
    carries its vertices and triangles."""
    ps, Rs = d.site_xpos[site], d.site_xmat[site].reshape(3, 3)
    robot = [
        g
        for g in range(m.ngeom)
        if m.body_rootid[m.geom_bodyid[g]] == root
        and int(m.geom_type[g]) in SHAPES
        and not m.geom(g).name.startswith(edits.TYRE)
    ]
    if visual_only:
        robot = [g for g in robot if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0]
    shapes = []
    for g in robot:
        kind = SHAPES[int(m.geom_type[g])]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, matmul(Rs.T, d.geom_xmat[g].reshape(3, 3)).ravel())
        rgba = m.mat_rgba[m.geom_matid[g]] if m.geom_matid[g] >= 0 else m.geom_rgba[g]
        shape = {
            "name": m.geom(g).name or f"geom{g}",
            "type": kind,
            "size": [round(float(x), 9) for x in m.geom_size[g, : SIZE_LEN[kind]]],
            "pos": [round(float(x), 9) for x in matmul(Rs.T, (d.geom_xpos[g] - ps)[:, None])[:, 0]],
            "quat": [round(float(x), 9) for x in quat],
            "rgba": [round(float(x), 6) for x in rgba],
        }
        if kind == "mesh":
            shape |= mesh_shape(m, g)
        shapes.append(shape)
    return shapes


def mesh_shape(m: mujoco.MjModel, g: int) -> dict:
    """A mesh geom's vertices (V, 3) float32 and triangles (F, 3) int32, in the geom's frame."""
    mesh = int(m.geom_dataid[g])
    v0, nv = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
    f0, nf = int(m.mesh_faceadr[mesh]), int(m.mesh_facenum[mesh])
    return {
        "mesh": m.mesh(mesh).name or f"mesh{mesh}",
        "vertices": m.mesh_vert[v0 : v0 + nv].astype(np.float32),
        "faces": m.mesh_face[f0 : f0 + nf].astype(np.int32),
    }
