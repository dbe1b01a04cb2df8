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
