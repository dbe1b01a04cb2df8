"""What a MuJoCo robot says of itself: why its state is not one to go on from (in words, with the
state's numbers), MuJoCo's warnings, the ``[plant]`` keys it found in its model, and what is
simulated (its provenance, for config.toml). :class:`MujocoReport` is the part of
:class:`~mlpfac.plants.mujoco.plant.MujocoPlant` that says it.
"""

from __future__ import annotations

import math

import mujoco

from mlpfac.plants.model_file import is_menagerie, menagerie_version
from mlpfac.plants.mujoco import compiled as K  # noqa: N812 - the kernel's layout constants, K.F_DT ...

DIVERGENCE_WARNINGS = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")  # MuJoCo resets the data on these


class MujocoReport:
    """diverged / why / found / provenance of the MuJoCo plant (its attributes are :class:`MujocoPlant`'s)."""

    def mujoco_warnings(self) -> dict[str, int]:
        """MuJoCo's warning counters that are not zero, by name (``{}`` when all is well)."""
        return {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(self.data.warning) if w.number}

    def diverged(self) -> str | None:
        """Why the robot's state is not one to go on from (:func:`mlpfac.plants.mujoco.compiled.diverged`), or None."""
        return self.why(K.diverged(self._args))

    def why(self, code: int) -> str | None:
        """The words for a divergence code of the compiled step, with the current state's numbers."""
        if code == K.WARNED:
            said = K.WARNINGS[-1].rstrip(".") if K.WARNINGS else "a warning"
            return f"MuJoCo warned: {said}; the simulation is not to be trusted from here"
        if code == K.RESET:
            bad = [w for w in DIVERGENCE_WARNINGS if self.data.warning[getattr(mujoco.mjtWarning, w)].number]
            return f"MuJoCo {' '.join(bad) or 'reset'}: the simulation became unstable and was reset"
        if code == K.NOT_FINITE:
            return "non-finite MuJoCo state"
        if code == K.LIFTED:
            lift = float(self._site_xpos[2]) - self.ground(*self._site_xpos[:2]) - self._z_rest  # above the ground
            return f"the robot left the floor (axle {lift * 1e3:.0f} mm above its rest height)"
        if code == K.TIPPED:
            up = float(self.data.xmat[self._root][8])  # world z component of the chassis z axis
            return f"the robot tipped over (chassis up axis {math.degrees(math.acos(max(-1.0, up))):.0f} deg from vertical)"
        return None

    def found(self) -> dict:
        """The ``[plant]`` keys the scenario left unset and the model answered, with their values:
        written into the scenario's table, so that its config.toml re-runs the same robot."""
        values = {k: getattr(self.config, k) for k in self.robot.found}
        return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}

    def provenance(self) -> dict:
        """What is simulated, for config.toml: the model file and the hash of the compiled model, and
        the geometry, limits and timing read from it."""
        m, (tl, tr) = self.model, self._torque_max
        out = {
            "model": self.config.model if is_menagerie(self.config.model) else str(self.config.path),
            "model_sha256": self.robot.sha256,
            "mujoco": mujoco.__version__,
            "timestep_s": float(m.opt.timestep),
            "substeps": self.n_substeps,
            "wheel_radius_m": self.real_radius,
            "track_m": self._real_track,
            "ik_wheel_radius_m": float(self.ik_radius),
            "ik_track_m": float(self.ik_track),
            "max_wheel_speed_rad_s": self.max_wheel_speed if self.max_wheel_speed is not None else "none",
            "torque_limit_Nm": [float(tl), float(tr)] if math.isfinite(tl + tr) else "none",
            "mass_kg": float(m.body_subtreemass[self._root]),
            "robot": self.robot.description,
        }
        if self.robot.found:
            out["found"] = list(self.robot.found)
        if is_menagerie(self.config.model):
            out |= {"model_file": str(self.config.path), "mujoco_menagerie": menagerie_version()}
        if self.robot.locked:
            out["locked_joints"] = list(self.robot.locked)
        if self.terrain is not None:
            out["world"] = self.world_said()
        if self.world_need():  # the run's world: line
            out["world_need"] = self.world_need()
        warning = self.world_warning()
        if warning:  # said first by `mlpfac run`
            out["world_warning"] = warning
        return out
