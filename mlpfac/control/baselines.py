"""Controllers with one interface: the adaptive MLP-EKF law (:mod:`mlpfac.control.adaptive.controller`), Corradini's
law with the nominal functions, and Kanayama's law. Any controller runs on any plant.

``step(e_k, r_k)`` takes the tracking error (2) and the reference sample
r_k = (x_r, y_r, theta_r, v_r, omega_r) and returns u_k = (v, omega).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from mlpfac.control.law import Law
from mlpfac.control.plugins import Plugin, one_line
from mlpfac.control.variants import CONTROLLERS  # noqa: F401 (the shipped names, as mlpfac.control.baselines.CONTROLLERS)
from mlpfac.exceptions import ConfigError, PluginError
from mlpfac.jit import as_rows

MAX_TELEMETRY = 256  # values per telemetry key of a user's controller


class Controller(Protocol):
    """The contract every controller keeps, the shipped ones and a user's own (:mod:`mlpfac.control.plugins`
    turns a name into a class; :class:`PluginController` steps a user's class).

    - a class, built as ``Class(T=<control period in s>, **params)``; ``params`` are the scenario's
      ``[controller.params]`` table;
    - ``step(e, r) -> (v, omega)`` for one run: ``e`` = (e1, e2, e3), the tracking error (2) of the
      measured pose, in the robot's frame (e1 ahead, e2 to the left, e3 = theta_r - theta wrapped);
      ``r`` = (x_r, y_r, theta_r, v_r, omega_r), the
      reference sample; the command (v [m/s], omega [rad/s]) goes to the robot's inverse kinematics;
    - optional ``reset(rng)``: called before every run with a seeded ``numpy.random.Generator``
      (the run's controller stream), so one seed gives the same run every time;
    - optional ``telemetry() -> dict``: floats or small arrays (at most 256 values each), the same
      keys and shapes every step; recorded in ``run.rrd`` under ``ctrl/<key>``; keys of at most 8
      values are in metrics.json (``ctrl_final``: the last step's). Two keys have the adaptive
      scheme's meaning: ``z`` (weights: ``max_abs_weight``) and ``mean_diag_P`` (``mean_diag_P_final``);
    - optional ``name`` (str): the controller's name in folders and tables (default: the class name;
      not one of the shipped names);
    - optional ``labels``: ``{telemetry key: [component names]}`` for the viewer;
    - optional batch form, for ``--batched``: ``batched = True``, and then ``reset`` may be given a list
      of B generators, after which ``step`` gets e of shape (B, 3) and returns (B, 2), and telemetry
      values have a leading B axis. Without it, a batched sweep runs such a controller's seeds one by one.

    A ``step`` that returns a command of another shape, or NaN / inf, ends that run as ``diverged``
    with the reason; an exception in the controller's own code is a :class:`~mlpfac.exceptions.PluginError`
    (the run fails, with the controller's traceback).
    """

    name: str
    labels: dict[str, list[str]]

    def reset(self, rng: np.random.Generator) -> None: ...

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray: ...

    def telemetry(self) -> dict[str, np.ndarray | float]: ...


class Stepped(Protocol):
    """What the closed loop (:mod:`mlpfac.loop`) steps: every controller
    :func:`mlpfac.loop.factory.make_controller` builds, a shipped one or a user's through
    :class:`PluginController` (or :class:`~mlpfac.control.torque.TorquePluginController`). Batch-first:
    ``reset`` is given one generator or a list of B, and then ``step`` takes (B, ...) arrays and
    returns (B, 2). The members with a value are the defaults a controller takes by naming this class
    as its base; the loop reads them without asking whether they are there."""

    name: str
    labels: dict[str, list[str]]
    level: ClassVar[str] = "velocity"
    """``"velocity"``: ``step(e, r) -> (v, omega)``; ``"torque"``: ``step(obs) -> wheel torques``
    (:mod:`mlpfac.control.torque`)."""
    why: Mapping[int, str] = MappingProxyType({})
    """The seeds the controller stopped itself (a user's command that is none), and why."""

    def reset(self, rng) -> None: ...

    def step(self, *args) -> np.ndarray: ...

    def telemetry(self) -> dict[str, np.ndarray | float]: ...

    def drop(self, b: int) -> None:
        """Seed b stopped (it diverged): a batched controller steps it no more. Nothing by default."""

    def watch(self, plants: list) -> None:
        """The run's plants, one per seed, reset, before the first step: ``limit`` reads the robot's
        true state from them (:mod:`mlpfac.control.mpc`). Nothing by default: no other controller
        sees more of the robot than its measurements."""


@runtime_checkable
class LawKernel(Protocol):
    """A controller whose law the compiled closed loop runs (:mod:`mlpfac.loop.compiled`)."""

    def law_kernel(self, k: int = 0) -> tuple[int, np.ndarray, np.ndarray] | None:
        """(the law's number, its constants, what it is told (none: empty)) from step k on, for
        :func:`mlpfac.control.oracle.told_step` (:func:`mlpfac.control.law.law_step` where it is told
        nothing); None where its step is not one kernel."""
        ...


@runtime_checkable
class StateKernel(Protocol):
    """A controller whose whole step the compiled closed loop may run: the adaptive scheme."""

    def kernel_state(self, b: int):
        """Seed b's :class:`~mlpfac.control.adaptive.kernels.AdaptiveState` after ``reset`` (views of
        the controller's own arrays), or None when this controller's step is not one kernel."""
        ...


class Corradini(Stepped):
    """The non-adaptive law (35) given the nominal functions h1 = T e2, h2 = T v_r cos e3, h5 = T omega_r."""

    name = "corradini"
    labels: dict[str, list[str]] = {"h_hat": ["h1", "h2", "h5"]}

    def __init__(self, law: Law, T: float) -> None:
        self.T = float(T)
        self.law = law
        self._limits = (
            np.inf if law.v_max is None else float(law.v_max),
            np.inf if law.omega_max is None else float(law.omega_max),
        )

    def reset(self, rng) -> None:
        from mlpfac.control.law import corradini_step
        from mlpfac.jit import seeds

        rngs, self.single = seeds(rng)
        T = self.T
        self._kernel = corradini_step
        self._h, self._u = np.zeros((len(rngs), 3)), np.zeros((len(rngs), 2))
        self._tele = {"h_hat": self._h[0] if self.single else self._h}
        corradini_step(np.zeros((0, 3)), 1.0, 0.0, T, *self.law.lambdas, *self._limits, self._h[:0], self._u[:0])

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        E = as_rows(e, 3)
        self._kernel(E, float(r[3]), float(r[4]), self.T, *self.law.lambdas, *self._limits, self._h, self._u)
        return self._u[0].copy() if self.single else self._u

    @property
    def h_hat(self) -> np.ndarray:
        return self._h[0] if self.single else self._h

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele

    def law_kernel(self, k: int = 0) -> tuple[int, np.ndarray, np.ndarray]:
        """The law for the compiled closed loop: (its number, its constants, nothing told) (:func:`mlpfac.control.law.law_step`)."""
        from mlpfac.control.law import CORRADINI

        return CORRADINI, np.array([self.T, *self.law.lambdas, *self._limits], dtype=float), np.zeros(0)


@dataclass(frozen=True)
class KanayamaGains:
    Kx: float = 10.0  # 1/s, on e1
    Ky: float = 64.0  # 1/m^2, on e2
    Ktheta: float = 16.0  # 1/m, on sin e3

    def __post_init__(self) -> None:
        for name in ("Kx", "Ky", "Ktheta"):
            if not getattr(self, name) > 0:
                raise ConfigError(name, f"Kanayama gains must be positive, got {getattr(self, name)}")


class Kanayama(Stepped):
    """Kanayama et al.'s law: v = v_r cos e3 + Kx e1, omega = omega_r + v_r (Ky e2 + Ktheta sin e3)."""

    name = "kanayama"
    labels: dict[str, list[str]] = {}

    def __init__(self, law: Law, gains: KanayamaGains, T: float) -> None:
        self.T = float(T)
        self.law = law  # only its limits are used
        self.g = gains
        self._consts = (
            float(gains.Kx),
            float(gains.Ky),
            float(gains.Ktheta),
            np.inf if law.v_max is None else float(law.v_max),
            np.inf if law.omega_max is None else float(law.omega_max),
        )

    def reset(self, rng) -> None:
        from mlpfac.control.law import kanayama_step
        from mlpfac.jit import seeds

        rngs, self.single = seeds(rng)
        self._kernel = kanayama_step
        self._u = np.zeros((len(rngs), 2))
        self._tele: dict = {}
        kanayama_step(np.zeros((0, 3)), 1.0, 0.0, *self._consts, self._u[:0])  # load the kernel before the run

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        E = as_rows(e, 3)
        self._kernel(E, float(r[3]), float(r[4]), *self._consts, self._u)
        return self._u[0].copy() if self.single else self._u

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele

    def law_kernel(self, k: int = 0) -> tuple[int, np.ndarray, np.ndarray]:
        """The law for the compiled closed loop: (its number, its constants, nothing told) (:func:`mlpfac.control.law.law_step`)."""
        from mlpfac.control.law import KANAYAMA

        return KANAYAMA, np.array(self._consts, dtype=float), np.zeros(0)


class PluginController(Stepped):
    """A plug-in stepped as the runner steps every controller (a batch of B seeds, arrays (B, ...)):
    one instance per seed, or one instance in its batch form. What the controller's own code
    raises becomes a :class:`PluginError`; a bad command ends its seed as diverged (``why``)."""

    level = "velocity"  # it commands (v, omega) (mlpfac.control.torque: the wheels' torques)

    def __init__(self, plugin: Plugin, T: float, instance: object | None = None) -> None:
        self.plugin, self.T = plugin, float(T)
        self.name = plugin.name
        cls = plugin.cls if plugin.cls is not None else type(instance)
        labels = getattr(cls, "labels", None)
        self.labels = dict(labels) if isinstance(labels, dict) else {}
        self._given = instance
        self.why: dict[int, str] = {}

    def _call(self, what: str, fn, *args):
        try:
            return fn(*args)
        except (KeyboardInterrupt, PluginError):
            raise
        except (Exception, SystemExit) as err:  # sys.exit() in a controller is its failure, not the command's
            raise PluginError(self.name, what, err) from err

    def reset(self, rngs) -> None:
        rngs = [rngs] if isinstance(rngs, np.random.Generator) else list(rngs)
        self.B, self.why, self.live = len(rngs), {}, list(range(len(rngs)))
        self._keys: tuple[str, ...] | None = None
        make = self.plugin.cls
        if self.plugin.batched:
            self.objs = [self._given if self._given is not None else self._call("__init__", self._new, make)]
        elif self._given is not None and self.B > 1:
            raise ValueError("a controller object runs one seed; pass its class to run a batch")
        else:
            self.objs = (
                [self._given] if self._given is not None else [self._call("__init__", self._new, make) for _ in rngs]
            )
        # the contract's optional members, looked up once: reset, telemetry, a batch form's drop
        one = self.objs[0]
        self._telemetry = hasattr(one, "telemetry")
        self._drop = getattr(one, "drop", None) if self.plugin.batched else None
        if not hasattr(one, "reset"):
            return
        if self.plugin.batched:
            self._call("reset", one.reset, rngs if self.B > 1 or self._given is None else rngs[0])
            return
        for obj, rng in zip(self.objs, rngs, strict=True):
            self._call("reset", obj.reset, rng)

    def _new(self, cls: type):
        return cls(T=self.T, **self.plugin.params)

    @property
    def whole_batch(self) -> bool:
        """The class is stepped once for all seeds, with arrays (B, ...); False for a given object
        running one seed (arrays without the batch axis) and for one instance per seed."""
        return self.plugin.batched and (self.B > 1 or self._given is None)

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        # copies, in every form: what the controller writes into them is its own, never the runner's
        # reference or errors (nor another seed's)
        return self._commands(
            lambda: self._call("step", self.objs[0].step, e.copy() if self.whole_batch else e[0].copy(), r.copy()),
            lambda b: self._call("step", self.objs[b].step, e[b].copy(), r.copy()),
        )

    def _commands(self, whole, seed, what: str = "(v, omega)") -> np.ndarray:
        """(B, 2) commands: ``whole()`` for a batched class ((B, 2), or (2,) for a given object running
        one seed), else ``seed(b)`` for each live seed. A seed whose command is none (``_command``)
        is stopped with the reason, NaN in its row: in a batch, only the seeds whose row is not
        finite, each with the reason its one-at-a-time run gives; a batch of the wrong shape or type, every seed."""
        u = np.full((self.B, 2), np.nan)
        if self.plugin.batched:
            out = self._command(whole(), (self.B, 2) if self.whole_batch else (2,), what, finite=False)
            if isinstance(out, str):
                self.why.update(dict.fromkeys(self.live, out))
                return u
            seed = out.reshape(self.B, 2).__getitem__  # each live seed's row, checked as its own command
        for b in self.live:
            row = self._command(seed(b), (2,), what)
            if isinstance(row, str):
                self.why[b] = row
            else:
                u[b] = row
        return u

    @staticmethod
    def _command(out, shape: tuple[int, ...], what: str = "(v, omega)", finite: bool = True) -> np.ndarray | str:
        """The command as an array of ``shape`` (finite unless ``finite`` is False), or why it is not one."""
        try:
            u = np.asarray(out, dtype=float)
        except (TypeError, ValueError):
            return f"step returned {type(out).__name__}, not {what}"
        if u.shape != shape:
            return f"step returned shape {u.shape}, expected {shape} {what}"
        if finite and not np.isfinite(u).all():
            return f"step returned a non-finite command {np.array2string(u, precision=3)}"
        return u

    def telemetry(self) -> dict[str, np.ndarray]:
        objs = self.objs
        if not self._telemetry:
            return {}
        if self.plugin.batched:
            rows = [self._call("telemetry", objs[0].telemetry)]
        else:  # a seed that stopped is not asked again: its last row stands (the runner keeps no more rows of it)
            rows = self._rows = [
                self._call("telemetry", o.telemetry) if b in self.live or self._keys is None else self._rows[b]
                for b, o in enumerate(objs)
            ]
        if self._keys is None:
            self._keys = tuple(rows[0]) if isinstance(rows[0], dict) else ()
            self._shapes: dict[str, tuple] = {}
        out = {}
        for key in self._keys:
            try:
                vals = [np.asarray(row[key], dtype=float) for row in rows]
            except (KeyError, TypeError, ValueError) as err:
                raise PluginError(self.name, "telemetry", ValueError(f"key {key!r}: {one_line(err)}")) from None
            v = np.stack(vals) if not self.plugin.batched else vals[0]
            if self.plugin.batched and (self.B == 1 and self._given is not None):
                v = v[None]
            shape = self._shapes.setdefault(key, v.shape)
            if v.shape != shape or v[0].size > MAX_TELEMETRY:
                raise PluginError(
                    self.name,
                    "telemetry",
                    ValueError(
                        f"key {key!r} has shape {v.shape[1:]}; each key keeps one shape of at most {MAX_TELEMETRY} values"
                    ),
                )
            out[key] = v
        return out

    def drop(self, b: int) -> None:
        if b in self.live:
            self.live.remove(b)
        if self._drop is not None:
            self._call("drop", self._drop, b)
