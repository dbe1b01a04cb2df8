"""A folder matplotlib can write its configuration and font cache into: the user's own, or, where
that cannot be written (a read-only HOME on a lab's shared machine), a temporary one removed at
exit, so that matplotlib warns of nothing on stderr."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path


def _writable(path: Path) -> bool:
    """Whether matplotlib can make (as it would) and write the folder ``path``."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(path, os.W_OK | os.X_OK)


def quiet_config() -> None:
    """Set MPLCONFIGDIR to a temporary folder when matplotlib's own folders cannot be written
    (before matplotlib is imported; a child process inherits it)."""
    if os.environ.get("MPLCONFIGDIR"):
        return
    try:
        home = Path.home()
    except (RuntimeError, KeyError):
        home = Path("/nonexistent")
    config = Path(os.environ.get("XDG_CONFIG_HOME") or home / ".config") / "matplotlib"
    cache = Path(os.environ.get("XDG_CACHE_HOME") or home / ".cache") / "matplotlib"
    if _writable(config) and _writable(cache):
        return
    tmp = tempfile.mkdtemp(prefix="mlpfac-matplotlib-")
    atexit.register(shutil.rmtree, tmp, True)
    os.environ["MPLCONFIGDIR"] = tmp
