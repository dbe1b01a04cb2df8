"""Where a robot's MJCF comes from: a file, or a MuJoCo Menagerie robot by name.

``model = "menagerie:pal_tiago/scene_velocity"`` names a Menagerie robot and entry point; the
``mujoco-menagerie`` package (the optional extra ``mlpfac[menagerie]``) resolves it, from the local
Menagerie checkout named by the environment variable ``MENAGERIE_ROOT`` when it is set, else from
its download cache (downloading the model on first use). The files are used as shipped: what the
plant needs beyond them is the scenario's ``[plant]`` keys and :mod:`mlpfac.plants.mjcf.edits`.
"""

from __future__ import annotations

import hashlib
import importlib.resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mlpfac.exceptions import ConfigError, UnavailableError

if TYPE_CHECKING:
    import mujoco

MENAGERIE = "menagerie:"
FIX = "set MENAGERIE_ROOT to a local MuJoCo Menagerie checkout, or run online so that mujoco-menagerie can download it"


def shipped_model() -> str:
    """The shipped robot's scene (models/scene.xml, installed as package data mlpfac.models)."""
    return str(importlib.resources.files("mlpfac.models") / "scene.xml")


def is_menagerie(model: str) -> bool:
    return model.startswith(MENAGERIE)


def menagerie_name(model: str) -> tuple[str, str]:
    """(robot, entry point) of ``"menagerie:ROBOT/ENTRY"`` (entry "" for the robot's default scene)."""
    robot, _, entry = model[len(MENAGERIE) :].partition("/")
    if not robot:
        raise ConfigError(
            "model", f"expected 'menagerie:ROBOT/ENTRY' (e.g. menagerie:pal_tiago/scene_velocity), got {model!r}"
        )
    return robot, entry


def model_path(model: str) -> Path:
    """The MJCF file ``model`` names (a Menagerie robot is resolved, and downloaded if need be)."""
    if not is_menagerie(model):
        path = Path(model).absolute()
        if not path.is_file():
            raise ConfigError(str(path), "MJCF model file not found")
        return path
    robot, entry = menagerie_name(model)
    try:
        import mujoco_menagerie as mm
    except ImportError:
        raise UnavailableError(
            "model", f"{model} needs the mujoco-menagerie package: pip install 'mlpfac[menagerie]'"
        ) from None
    try:
        r = mm.get(robot)
        file = r.entry(entry or None).file  # an unknown entry point is known without a download
        return r.path(progress=None) / file
    except mm.UnknownRobotError as err:
        raise ConfigError("model", f"{model}: {err}") from None
    except mm.UnknownEntryPointError as err:
        raise ConfigError("model", f"{model}: {err}") from None
    except mm.MenagerieError as err:
        raise UnavailableError("model", f"{model} is not available here ({err}): {FIX}") from None


def menagerie_version() -> str | None:
    """The installed mujoco-menagerie package's version and registry commit, for provenance."""
    try:
        import mujoco_menagerie as mm
    except ImportError:
        return None
    return f"{mm.__version__} (registry {mm.commit()[:7]})"


def load_spec(model: str) -> tuple[mujoco.MjSpec, Path]:
    """The model's spec as its files describe it, and the file it came from."""
    import mujoco  # here, not at the top: a listing reads scenarios without MuJoCo

    path = model_path(model)
    try:
        return mujoco.MjSpec.from_file(str(path)), path
    except ValueError as err:
        raise ConfigError(str(path), f"MuJoCo cannot load the model: {' '.join(str(err).split())}") from None


def model_fingerprint(model: str) -> str:
    """sha256 of the compiled model (MuJoCo's binary MJB): what is simulated, included files and
    meshes too. Compiled afresh each time: a file that changed is never mistaken for the old one."""
    spec, path = load_spec(model)
    try:
        return fingerprint(spec.compile())
    except ValueError as err:
        raise ConfigError(str(path), f"MuJoCo cannot load the model: {' '.join(str(err).split())}") from None


def fingerprint(model: mujoco.MjModel) -> str:
    import mujoco

    buf = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return hashlib.sha256(buf.tobytes()).hexdigest()
