"""The project's error types: each carries one sentence a user can act on."""

from __future__ import annotations


class MlpfacError(Exception):
    """Base class: the command line prints ``str(err)`` on one line and exits with code 2."""


class ConfigError(MlpfacError, ValueError):
    """A scenario, model or parameter is invalid. The message names the file/key and the problem."""

    def __init__(self, where: str, what: str) -> None:
        super().__init__(f"{where}: {what}" if where else what)
        self.where = where
        self.what = what

    def __reduce__(self):  # picklable, so an error raised in a worker process reaches the parent
        return (type(self), (self.where, self.what))


class UnavailableError(ConfigError):
    """What a run needs is not on this machine (a MuJoCo Menagerie robot offline): bad input for a
    run, a dataset skipped, with this reason, for ``mlpfac report --verify``."""


class ScriptStopped(BaseException):  # noqa: N818 - not an error: the import of a script ends there
    """Raised in a sweep worker by a call of mlpfac's API at the top level of a user's script that
    the worker imports for its controller class: the import ends there, with what the script
    defined above the call (:func:`mlpfac.control.plugins.load_target`), so that a script needs no
    ``if __name__ == "__main__":`` and its sweep does not start again in every worker."""


class OutputError(MlpfacError):
    """Writing results failed (a full disk, a lost permission): one line naming the path."""


class WorkerLostError(MlpfacError):
    """A local worker process died (killed from outside, out of memory): the pool cannot go on."""


class PluginError(MlpfacError):
    """A user's controller raised in its own code: that run fails (exit 1, not 2: the fault is the
    controller's, not the input's). ``traceback`` is the
    controller's part of the traceback (frames in mlpfac's own files left out)."""

    def __init__(self, controller: str, what: str, err: BaseException | None = None, traceback: str = "") -> None:
        self.controller, self.what = controller, what
        self.text = f"controller {controller!r} raised in {what}" + (f": {type(err).__name__}: {err}" if err else "")
        self.traceback = traceback or (_user_traceback(err) if err is not None else "")
        super().__init__(self.text)

    def __reduce__(self):  # picklable, so it reaches the parent of a worker process
        return (type(self), (self.controller, self.what, None, self.traceback), {"text": self.text, "args": self.args})

    def report(self) -> str:
        """The message and the controller's traceback: what stderr and error.txt get."""
        return f"{self.traceback.rstrip()}\n{self.text}\n" if self.traceback else f"{self.text}\n"


def _user_traceback(err: BaseException) -> str:
    import traceback
    from pathlib import Path

    ours = str(Path(__file__).resolve().parent)
    frames = [
        f for f in traceback.extract_tb(err.__traceback__) if not str(Path(f.filename).resolve()).startswith(ours)
    ]
    lines = ["Traceback (most recent call last, the controller's own code):\n", *traceback.format_list(frames)]
    return "".join(lines + traceback.format_exception_only(err))
