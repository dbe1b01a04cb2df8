"""A trained policy as a controller: a small MLP's weights and its scaling in a plain ``.npz`` file,
evaluated by our own kernel (no learning library, the same bits on every machine).

A policy is named like any controller: ``policy-dr`` (shipped with mlpfac, trained over randomized
robots: ``examples/train_policy.py``, docs/envs.md) or ``path/to/policy.npz``. It commands (v, omega)
from what a kinematic plug-in is given, (e, r), and its own last command. Its inputs are
dimensionless where the robot sets the scale, so that it can run on a robot it was not trained on:

    x = clip(f / obs_scale, -obs_clip, obs_clip)
    f = (e1, e2, sin e3, 1 - cos e3, v_r / v_max, omega_r / omega_max, v_prev / v_max, omega_prev / omega_max)

with (v_max, omega_max) the controller's limits (``[controller] v_max``, ``omega_max``: on another
robot ``--robot`` sets them from its wheels, :mod:`mlpfac.scenario.on_robot`). Hidden layers are
tanh, the output layer linear, clipped to [-1, 1]: a = (a_v, a_omega), and the command is

    u = ff + act_scale * a * (v_max, omega_max),   ff = (v_r, omega_r) when ``feedforward``, else 0.

The file's arrays (:func:`save` writes them, :func:`read_policy` checks them):

- ``format``: ``"mlpfac-policy-1"``; ``features``: ``"tracking-1"`` (the f above);
- ``W0, b0, W1, b1, ...``: layer i maps ``W_i @ x + b_i``, ``W_i`` (out, in), the last layer's out 2;
- ``obs_scale`` (8,) > 0, ``obs_clip`` (> 0), ``act_scale`` (2,) > 0, ``feedforward`` (0 or 1);
- any other array (``about``: the command that trained it, say) is kept and not read.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import io
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mlpfac.control.baselines import Stepped
from mlpfac.control.law import Law
from mlpfac.control.variants import POLICIES
from mlpfac.elementary import cos, sin, tanh
from mlpfac.exceptions import ConfigError
from mlpfac.jit import as_rows, kernel

FORMAT = "mlpfac-policy-1"
FEATURES = "tracking-1"
N_IN = 8  # the features f
MAX_PARAMS = 1_000_000  # weights of a policy, at most (a small MLP: a step is microseconds)
MAX_LAYERS = 8
POLICY_MAX = 64 * 2**20  # bytes of a policy file, at most (MAX_PARAMS float64 weights are 8 MB)


def shipped_dir() -> Path:
    """The folder of the shipped policies (policies/, installed as package data mlpfac.policies)."""
    return Path(str(importlib.resources.files("mlpfac.policies")))


def is_policy_spec(name: str) -> bool:
    """Whether a controller's name is a policy: a shipped one, or a ``.npz`` file."""
    return name in POLICIES or name.endswith(".npz")


def policy_file(name: str) -> Path:
    """The file a policy's name is: ``policies/NAME.npz`` for a shipped one, else the path itself."""
    return shipped_dir() / f"{name}.npz" if name in POLICIES else Path(name).expanduser()


def policy_name(name: str) -> str:
    """A policy's name in folders and tables: the shipped name, or its file's stem."""
    return name if name in POLICIES else Path(name).stem


@dataclass(frozen=True)
class PolicyFile:
    """A policy read and checked: its layers packed as :func:`policy_step` takes them."""

    path: str
    sha256: str
    sizes: np.ndarray  # (L + 1,) int64: inputs, then each layer's outputs
    params: np.ndarray  # every layer's W (row-major) then b, in order
    obs_scale: np.ndarray  # (N_IN,)
    obs_clip: float
    act_scale: np.ndarray  # (2,)
    feedforward: bool

    @property
    def target(self) -> str:
        return self.path

    def provenance(self) -> dict:
        return {"target": self.path, "origin": "policy file", "sha256": self.sha256}


def read_policy(path: str | Path, where: str) -> PolicyFile:
    """The policy in ``path``, every array checked: a ConfigError naming ``where`` (the flag or the
    file's key) and the array for a file that is not an npz, an array missing, a shape that does not
    chain, a weight that is not finite."""
    from mlpfac.io.files import NotAFileError, read_regular

    path = Path(path)
    try:
        data = read_regular(path, POLICY_MAX)  # a FIFO or a device refused at once, never read whole
    except FileNotFoundError:
        raise ConfigError(where, f"{path}: no such policy file") from None
    except NotAFileError as err:
        raise ConfigError(where, f"{path}: {err} (a policy file)") from None
    except OSError as err:
        raise ConfigError(where, f"{path}: cannot read ({err.strerror or err})") from None
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:  # the bytes hashed, read once
            arrays = {k: z[k] for k in z.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as err:
        raise ConfigError(where, f"{path}: not a policy file (an .npz of arrays: {str(err).splitlines()[0]})") from None
    name = f"{where} ({path.name})"

    def array(key: str, shape: tuple | None = None) -> np.ndarray:
        if key not in arrays:
            raise ConfigError(name, f"no array {key!r} (a policy file holds {', '.join(REQUIRED)}, W0, b0, ...)")
        a = arrays[key]
        if a.dtype.kind not in "fiub":
            raise ConfigError(name, f"{key} holds {a.dtype}, not numbers")
        a = a.astype(float)
        if shape is not None and a.shape != shape:
            raise ConfigError(name, f"{key} has shape {a.shape}, expected {shape}")
        if not np.isfinite(a).all():
            raise ConfigError(name, f"{key} holds a value that is not finite")
        return a

    for key, want in (("format", FORMAT), ("features", FEATURES)):
        got = arrays.get(key)
        if got is None or got.shape != () or str(got) != want:
            raise ConfigError(name, f"{key} must be {want!r}, got {None if got is None else str(got)!r}")
    obs_scale, act_scale = array("obs_scale", (N_IN,)), array("act_scale", (2,))
    obs_clip, ff = float(array("obs_clip", ())), float(array("feedforward", ()))
    if not (obs_scale > 0).all() or not (act_scale > 0).all() or not obs_clip > 0:
        raise ConfigError(name, "obs_scale, obs_clip and act_scale must be positive")
    if ff not in (0.0, 1.0):
        raise ConfigError(name, f"feedforward is 0 or 1, got {ff:g}")
    layers = sum(1 for k in arrays if k.startswith("W") and k[1:].isdigit())
    if not 1 <= layers <= MAX_LAYERS:
        raise ConfigError(name, f"expected 1 to {MAX_LAYERS} layers W0, b0, W1, b1, ..., found {layers}")
    sizes, parts = [N_IN], []
    for i in range(layers):
        W = array(f"W{i}")
        out = 2 if i == layers - 1 else (W.shape[0] if W.ndim == 2 else -1)
        W = array(f"W{i}", (out, sizes[-1]))
        parts += [W.ravel(), array(f"b{i}", (out,))]
        sizes.append(out)
    params = np.concatenate(parts)
    if params.size > MAX_PARAMS:
        raise ConfigError(name, f"{params.size} weights; a policy has at most {MAX_PARAMS}")
    sha = hashlib.sha256(data).hexdigest()
    return PolicyFile(str(path.resolve()), sha, np.array(sizes, dtype=np.int64), params, obs_scale, obs_clip,
                      act_scale, bool(ff))  # fmt: skip


REQUIRED = ("format", "features", "obs_scale", "obs_clip", "act_scale", "feedforward")


def save(
    path: str | Path,
    layers: list[tuple[np.ndarray, np.ndarray]],
    obs_scale,
    obs_clip: float,
    act_scale,
    feedforward: bool,
    **about: str,
) -> PolicyFile:
    """Write a policy file (``layers``: (W, b) per layer, W (out, in)) and read it back, checked.
    ``about``: text kept beside the weights (how it was trained), one string per key."""
    arrays = {"format": np.array(FORMAT), "features": np.array(FEATURES)}
    arrays |= {"obs_scale": np.asarray(obs_scale, dtype=float), "obs_clip": np.array(float(obs_clip))}
    arrays |= {"act_scale": np.asarray(act_scale, dtype=float), "feedforward": np.array(float(bool(feedforward)))}
    for i, (W, b) in enumerate(layers):
        arrays[f"W{i}"], arrays[f"b{i}"] = np.asarray(W, dtype=float), np.asarray(b, dtype=float)
    arrays |= {key: np.array(str(text)) for key, text in about.items()}
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return read_policy(path, str(path))


@kernel()
def _features(e1, e2, e3, v_r, omega_r, v_prev, omega_prev, v_max, omega_max, scale, clip, x):
    """The scaled inputs x (N_IN,) of one seed (the module docstring's f)."""
    f = (e1, e2, sin(e3), 1.0 - cos(e3), v_r / v_max, omega_r / omega_max, v_prev / v_max, omega_prev / omega_max)
    for i in range(8):
        x[i] = min(max(f[i] / scale[i], -clip), clip)


@kernel("void(f8[:, ::1], f8[:, ::1], f8[:, ::1], f8, f8, f8[::1], f8, f8[:, ::1])")
def features(E, R, U_prev, v_max, omega_max, scale, clip, X):
    """The scaled inputs X (B, N_IN) of a batch whose rows have their own reference R (B, 2) =
    (v_r, omega_r): what a policy is given, for training one (``examples/policy/train_policy.py``)."""
    for b in range(E.shape[0]):
        _features(E[b, 0], E[b, 1], E[b, 2], R[b, 0], R[b, 1], U_prev[b, 0], U_prev[b, 1], v_max, omega_max, scale,
                  clip, X[b])  # fmt: skip


@kernel()
def mlp(sizes, params, x, work, out):
    """The MLP's output (sizes[-1],) for the input x: tanh hidden layers, a linear last one, each
    sum taken in index order (the same bits everywhere). ``work`` (2, max width) holds the layers'."""
    n_in = sizes[0]
    for i in range(n_in):
        work[0, i] = x[i]
    o, cur = 0, 0
    L = sizes.shape[0] - 1
    for layer in range(L):
        n, m = sizes[layer], sizes[layer + 1]
        nxt = 1 - cur
        for j in range(m):
            s = params[o + m * n + j]
            for i in range(n):
                s += params[o + j * n + i] * work[cur, i]
            work[nxt, j] = tanh(s) if layer < L - 1 else s
        o += m * n + m
        cur = nxt
    for j in range(sizes[L]):
        out[j] = work[cur, j]


@kernel(
    "void(f8[:, ::1], f8, f8, f8[:, ::1], f8, f8, i8[::1], f8[::1], f8[::1], f8, f8[::1], b1, f8[:, ::1], f8[:, ::1])"
)
def policy_step(E, v_r, omega_r, U_prev, v_max, omega_max, sizes, params, scale, clip, act, ff, A, U):
    """The policy's commands U (B, 2) for the errors E (B, 3) and its last commands U_prev (B, 2);
    A (B, 2) the network's outputs, clipped to [-1, 1]."""
    width = 0
    for s in sizes:
        width = max(width, s)
    work = np.empty((2, width))
    x, a = np.empty(8), np.empty(2)
    for b in range(E.shape[0]):
        _features(E[b, 0], E[b, 1], E[b, 2], v_r, omega_r, U_prev[b, 0], U_prev[b, 1], v_max, omega_max, scale,
                  clip, x)  # fmt: skip
        mlp(sizes, params, x, work, a)
        A[b, 0], A[b, 1] = min(max(a[0], -1.0), 1.0), min(max(a[1], -1.0), 1.0)
        v, w = act[0] * A[b, 0] * v_max, act[1] * A[b, 1] * omega_max
        U[b, 0], U[b, 1] = (v_r + v, omega_r + w) if ff else (v, w)


def limits(law: Law) -> tuple[float, float]:
    """The (v_max, omega_max) a policy's scaling takes: the controller's limits, which must be set."""
    if law.v_max is None or law.omega_max is None or not (math.isfinite(law.v_max) and math.isfinite(law.omega_max)):
        raise ConfigError(
            "[controller] v_max, omega_max",
            "a policy scales its inputs and commands by the controller's limits: set both (or run it with --robot)",
        )
    return float(law.v_max), float(law.omega_max)


class Policy(Stepped):
    """A policy file run as a controller: batch-first, its last command its own state (zero before
    its first step). Telemetry ``a``: the network's output (clipped), the command before scaling."""

    labels: dict[str, list[str]] = {"a": ["a_v", "a_omega"]}

    def __init__(self, policy: PolicyFile, name: str, T: float, law: Law) -> None:
        self.p, self.name, self.T = policy, name, float(T)
        self.v_max, self.omega_max = limits(law)

    def reset(self, rng) -> None:
        from mlpfac.jit import seeds

        rngs, self.single = seeds(rng)
        self._u = np.zeros((len(rngs), 2))
        self._prev = np.zeros((len(rngs), 2))
        self._a = np.zeros((len(rngs), 2))
        self._tele = {"a": self._a[0] if self.single else self._a}

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        p = self.p
        policy_step(as_rows(e, 3), float(r[3]), float(r[4]), self._prev, self.v_max, self.omega_max, p.sizes,
                    p.params, p.obs_scale, p.obs_clip, p.act_scale, p.feedforward, self._a, self._u)  # fmt: skip
        self._prev[:] = self._u
        return self._u[0].copy() if self.single else self._u.copy()

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele
