"""Your own controller in the testbed: how a name becomes a class (the contract it keeps is the
:class:`~mlpfac.control.baselines.Controller` protocol's docstring, and docs/controllers.md).

**Names** (``--controller``, ``--controllers``, ``[controller] name``, :func:`mlpfac.run`,
:func:`mlpfac.sweep`): a shipped controller; ``path/to/file.py:Class`` (relative to the current
folder on the command line, to the scenario file's folder in a scenario file); ``package.module:Class``
(importable); or a name an installed package registers in the entry-point group ``mlpfac.control.baselines``
(``name = "module:Class"``).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.control.variants import CONTROLLERS
from mlpfac.exceptions import ConfigError, ScriptStopped
from mlpfac.tables import FOLDER_NAME

LEVELS = ("velocity", "torque")  # what a controller commands: (v, omega), or the wheels' torques
GROUP = "mlpfac.control.baselines"  # the entry-point group an installed package registers controllers in
_LOCAL: dict[str, type] = {}  # classes handed to the Python API that no file or module names
USER_CODE = False  # a controller of the user's was resolved in this process (see mlpfac.cli.entry)
IMPORTING = 0  # a user's file is being imported (see mlpfac.sweeps.worker.not_in_a_worker)


@dataclass(frozen=True)
class Plugin:
    """A user's controller, resolved: what the scenario table names and what it ran."""

    spec: str  # as the table holds it: "/abs/file.py:Class", "package.module:Class" or an entry-point name
    target: str  # what is loaded: "/abs/file.py:Class" or "package.module:Class"
    name: str  # its name in folders, tables and metrics
    origin: str  # "file", "module", "entry point (DIST)" or "this process"
    sha256: str | None  # of the file that defines it (None: no file)
    batched: bool  # it has the batch form
    level: str = "velocity"  # "torque": step(obs) -> wheel torques (mlpfac.control.torque)
    params: dict = field(default_factory=dict, compare=False)
    cls: type | None = field(default=None, compare=False, repr=False)

    def provenance(self) -> dict:
        out = {"target": self.target, "origin": self.origin}
        return out | ({"sha256": self.sha256} if self.sha256 else {})


def is_plugin_spec(text: str) -> bool:
    """Whether a controller name is a plug-in (not one of the shipped controllers, nor a policy's
    ``.npz`` file: :mod:`mlpfac.control.policy`)."""
    return text not in CONTROLLERS and not text.endswith(".npz")


def absolute_spec(spec: str, base: Path) -> str:
    """``file.py:Class`` (or a policy's ``file.npz``) with a relative path made absolute against
    ``base``; other names unchanged."""
    path, sep, cls = spec.rpartition(":")
    if sep and path.endswith(".py") and not Path(path).expanduser().is_absolute():
        return f"{(base / Path(path).expanduser()).resolve()}:{cls}"
    if spec.endswith(".npz") and not Path(spec).expanduser().is_absolute():
        return str((base / Path(spec).expanduser()).resolve())
    return spec


def entry_points() -> dict[str, tuple[str, str]]:
    """Controllers registered by installed packages: name -> (``module:Class``, distribution)."""
    from importlib.metadata import entry_points as eps

    out = {}
    for ep in eps(group=GROUP):
        dist = ep.dist.name if getattr(ep, "dist", None) is not None else "?"
        out.setdefault(ep.name, (ep.value, dist))
    return out


def local_spec(cls: type) -> str:
    """A name for a class given to the Python API: its file or module if they name it, else this process's."""
    module = sys.modules.get(cls.__module__)
    qual = cls.__qualname__
    if "<locals>" not in qual and getattr(module, qual.split(".")[0], None) is not None:
        if cls.__module__ == "__main__" or cls.__module__.startswith("mlpfac_plugin_"):
            file = getattr(module, "__file__", None)
            if file and "." not in qual and Path(file).suffix == ".py":
                return f"{Path(file).resolve()}:{qual}"
        elif "." not in qual:
            return f"{cls.__module__}:{qual}"
    key = f"<local>:{qual}#{id(cls):x}"
    _LOCAL[key] = cls
    return key


def resolve(spec: str, params: dict | None, T: float, where: str, params_where: str = "[controller.params]") -> Plugin:
    """The plug-in a name refers to, checked against the contract; ConfigError naming ``where``
    (the flag, or the file and key) for a missing file, module or class, a class without ``step``,
    or parameters it does not accept (``params`` None: not checked). Nothing of the controller runs
    here but its module's import."""
    global USER_CODE
    USER_CODE = True
    origin = "module"
    target = spec
    if spec in _LOCAL:
        cls, sha, origin = _LOCAL[spec], None, "this process"
    elif spec.startswith("<local>:"):
        raise ConfigError(
            where,
            f"{spec.split('#')[0]} was a class given to the Python API in another process, which no file or "
            "module names: run it from Python again, or put it in a file and name it path/to/file.py:Class",
        )
    else:
        if ":" not in spec:
            found = entry_points().get(spec)
            if found is None:
                raise ConfigError(where, f"unknown controller {spec!r}; {_choices()}")
            target, origin = found[0], f"entry point ({found[1]})"
        cls, sha, kind = load_target(target, where)
        origin = "file" if kind == "file" else origin
    if not inspect.isclass(cls):
        raise ConfigError(where, f"{target} is not a class (a controller is a class with step(e, r))")
    if not callable(getattr(cls, "step", None)):
        raise ConfigError(
            where, f"{target} has no step(e, r) method (the contract: mlpfac.control.baselines.Controller)"
        )
    name = _name(cls, spec if origin.startswith("entry point") else None, where)
    level = getattr(cls, "level", "velocity")
    if level not in LEVELS:
        raise ConfigError(
            where, f"{target}.level is {level!r}; a controller's level is 'velocity' (the default) or 'torque'"
        )
    if params is not None:
        _check_params(cls, T, params, where, params_where, level == "torque")
    batched = getattr(cls, "batched", False) is True
    return Plugin(spec, target, name, origin, sha, batched, level, dict(params or {}), cls)


def _choices() -> str:
    eps = sorted(entry_points())
    return (
        f"choose one of {', '.join(CONTROLLERS)}"
        + (f", or an installed one: {', '.join(eps)}" if eps else "")
        + ", or your own as path/to/file.py:Class or package.module:Class"
    )


def _name(cls: type, entry: str | None, where: str) -> str:
    name = entry or getattr(cls, "name", None)
    if not isinstance(name, str):
        name = cls.__name__
    if not FOLDER_NAME.fullmatch(name):
        raise ConfigError(
            where, f"the controller's name {name!r} must be letters, digits and . _ + - (it names folders)"
        )
    if name in CONTROLLERS:
        raise ConfigError(
            where, f"the controller's name {name!r} is a shipped controller's; give the class another name"
        )
    return name


def load_target(target: str, where: str) -> tuple[object, str | None, str]:
    """The object ``module:Class`` or ``/path/file.py:Class`` names; (object, sha256 of its file, kind).
    A file is imported once per content (a module named by its sha256), so an edited file is new code.
    (A reference class of the user's is loaded here too: :mod:`mlpfac.scenario.own_reference`.)"""
    global IMPORTING, USER_CODE
    USER_CODE = True
    left, sep, attr = target.rpartition(":")
    if not sep or not left or not attr:
        raise ConfigError(where, f"{target!r}: name a class as path/to/file.py:Class or package.module:Class")
    if left.endswith(".py"):
        path = Path(left).expanduser()
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            raise ConfigError(where, f"{path}: no such file") from None
        except OSError as err:
            raise ConfigError(where, f"{path}: cannot read ({err.strerror or err})") from None
        sha = hashlib.sha256(data).hexdigest()
        mod_name = f"mlpfac_plugin_{sha[:16]}_{re.sub(r'[^A-Za-z0-9_]', '_', path.stem)}"
        main = getattr(sys.modules.get("__main__"), "__file__", None)
        if main and Path(main).resolve() == path.resolve():  # the running script: not run a second time
            mod_name = "__main__"
        module = sys.modules.get(mod_name)
        if module is None:
            spec = importlib.util.spec_from_file_location(mod_name, path)
            if spec is None or spec.loader is None:
                raise ConfigError(where, f"{path}: not a Python file")
            module = importlib.util.module_from_spec(spec)
            sys.modules[mod_name] = module
            IMPORTING += 1
            try:
                spec.loader.exec_module(module)
            except ScriptStopped:  # a sweep worker: the script's classes are defined above its call of mlpfac
                pass
            except BaseException as err:
                del sys.modules[mod_name]
                if isinstance(err, KeyboardInterrupt):
                    raise
                raise ConfigError(where, f"{path}: importing it raised {one_line(err)}") from None
            finally:
                IMPORTING -= 1
        kind = "file"
    else:
        try:
            module = importlib.import_module(left)
        except ModuleNotFoundError as err:
            raise ConfigError(where, f"no module named {err.name!r} (importing {left})") from None
        except (Exception, SystemExit) as err:
            raise ConfigError(where, f"importing {left} raised {one_line(err)}") from None
        file = getattr(module, "__file__", None)
        sha = _file_sha(file)
        kind = "module"
    obj = module
    for part in attr.split("."):
        obj = getattr(obj, part, None)
        if obj is None:
            raise ConfigError(where, f"{left} has no class {attr!r}")
    return obj, sha, kind


def _file_sha(file: str | None) -> str | None:
    try:
        return hashlib.sha256(Path(file).read_bytes()).hexdigest() if file else None
    except OSError:
        return None


def one_line(err: BaseException) -> str:
    text = f"{type(err).__name__}: {err}".splitlines()[0]
    tb = inspect.trace()[-1] if sys.exc_info()[0] is not None else None
    if isinstance(err, SyntaxError) and err.lineno:
        return f"{text} (line {err.lineno})"
    return text + (f" ({Path(tb.filename).name}, line {tb.lineno})" if tb is not None else "")


def _check_params(cls: type, T: float, params: dict, where: str, params_where: str, torque: bool = False) -> None:
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):
        return  # a class whose signature cannot be read is trusted
    given = {"T": T, "robot": None} if torque else {"T": T}
    for key in given:
        if key in params:
            raise ConfigError(f"{params_where} {key}", f"{key} is given by the testbed, not by [controller.params]")
    takes = any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
    if torque and "robot" not in sig.parameters and not takes:
        raise ConfigError(
            where,
            f"{cls.__name__} is a torque-level controller: it must take robot (Class(T=..., robot=..., **params))",
        )
    try:
        sig.bind(**given, **params)
    except TypeError as err:
        text = str(err)
        bad = re.search(r"keyword argument '(\w+)'", text)
        if bad and bad.group(1) not in given:
            raise ConfigError(f"{params_where} {bad.group(1)}", f"{cls.__name__} does not take it ({text})") from None
        if "T" not in sig.parameters and not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
            raise ConfigError(where, f"{cls.__name__}(T=..., **params) must take T, the control period in s") from None
        raise ConfigError(params_where, f"{cls.__name__}(T=..., **params): {text}") from None
