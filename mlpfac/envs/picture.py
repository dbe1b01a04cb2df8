"""``render_mode="rgb_array"``: a top view of an episode as an image (H, W, 3) uint8, drawn in numpy:
the reference's path in grey, the path driven so far in blue, the robot's pose in red (a dot and
its heading). What a video recorder (gymnasium's ``RecordVideo``) or a learning library asks for;
the rerun recording (``render_mode="human"``, ``record=``) is the one to browse."""

from __future__ import annotations

import numpy as np

SIZE = 256  # pixels a side
MARGIN = 0.1  # of the path's extent, around it
GREY, BLUE, RED = (170, 170, 170), (31, 119, 180), (214, 39, 40)


def top_view(ref_xy: np.ndarray, path_xy: np.ndarray, pose: np.ndarray, size: int = SIZE) -> np.ndarray:
    """The image: ``ref_xy`` (N, 2) and ``path_xy`` (M, 2) in metres, ``pose`` (x, y, theta)."""
    img = np.full((size, size, 3), 255, dtype=np.uint8)
    ref = ref_xy[np.isfinite(ref_xy).all(axis=1)]
    lo, hi = ref.min(axis=0), ref.max(axis=0)
    span = float(np.max(hi - lo)) * (1.0 + 2.0 * MARGIN) or 1.0
    centre = (lo + hi) / 2.0

    def pixels(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xy = xy[np.isfinite(xy).all(axis=1)]
        u = ((xy[:, 0] - centre[0]) / span + 0.5) * (size - 1)
        v = (0.5 - (xy[:, 1] - centre[1]) / span) * (size - 1)
        keep = (u >= 0) & (u <= size - 1) & (v >= 0) & (v <= size - 1)
        return np.round(v[keep]).astype(int), np.round(u[keep]).astype(int)

    img[pixels(ref)] = GREY
    if len(path_xy):
        img[pixels(path_xy)] = BLUE
    if np.isfinite(pose).all():
        ahead = pose[:2] + span / 20.0 * np.array([np.cos(pose[2]), np.sin(pose[2])])
        img[pixels(np.linspace(pose[:2], ahead, 12))] = RED
        r, c = pixels(pose[None, :2])
        for dr in range(-2, 3):
            for dc in range(-2, 3):
                img[np.clip(r + dr, 0, size - 1), np.clip(c + dc, 0, size - 1)] = RED
    return img
