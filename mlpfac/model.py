"""The tracking error (2) and the discrete error model e_k = f_{k-1} + G_{k-1} u_{k-1}, (4)-(6)."""

from __future__ import annotations

import numpy as np


def wrap(angle: np.ndarray | float) -> np.ndarray | float:
    """Angle wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def tracking_error(q: np.ndarray, q_r: np.ndarray) -> np.ndarray:
    """Eq. (2): the error of pose q = (x, y, theta) to q_r, in the robot's frame; e3 wrapped. (3,)"""
    c, s = np.cos(q[2]), np.sin(q[2])
    dx, dy = q_r[0] - q[0], q_r[1] - q[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap(q_r[2] - q[2])])


def pose_from_error(e: np.ndarray, q_r: np.ndarray) -> np.ndarray:
    """The pose q whose error (2) to q_r is e (the inverse of :func:`tracking_error`). (3,)"""
    theta = q_r[2] - e[2]
    c, s = np.cos(theta), np.sin(theta)
    return np.array([q_r[0] - (c * e[0] - s * e[1]), q_r[1] - (s * e[0] + c * e[1]), theta])


def f_true(e: np.ndarray, v_r: float, omega_r: float, T: float) -> np.ndarray:
    """Eq. (5): the drift of the Euler-discretised error dynamics (3). (3,)"""
    return np.array([e[0] + T * v_r * np.cos(e[2]), e[1] + T * v_r * np.sin(e[2]), e[2] + T * omega_r])


def G_true(e: np.ndarray, T: float) -> np.ndarray:
    """Eq. (6): the input matrix of the Euler-discretised error dynamics (3). (3, 2)"""
    return np.array([[-T, T * e[1]], [0.0, -T * e[0]], [0.0, -T]])


def h_true(e: np.ndarray, v_r: float, omega_r: float, T: float) -> np.ndarray:
    """Eq. (34) with the true functions: (h1, h2, h5) = (G_12, f_1 - e1, f_3 - e3). (3,)"""
    return np.array([T * e[1], T * v_r * np.cos(e[2]), T * omega_r])
