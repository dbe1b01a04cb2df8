"""Logging a run to rerun: the robot in 3D, a top view, the tracking error, the commands, every
network weight, the EKF's covariance, the plant events and the final status, with a default layout.

The only package that imports rerun: import it lazily, so runs without logging do not pay for it.

- :mod:`~mlpfac.log.sinks`: opening outputs (file, viewer, web viewer) and starting viewers; ``make_sink``
- :mod:`~mlpfac.log.recorder`: ``RerunSink``, the runner's ``begin`` / ``flush`` / ``end``
- :mod:`~mlpfac.log.schema`: what each record array and telemetry key becomes (paths, names, colours)
- :mod:`~mlpfac.log.series`: a record's rows as scalar columns, sent in batches
- :mod:`~mlpfac.log.scene`: robot shapes, poses and paths in the 3D world and the top view
- :mod:`~mlpfac.log.layout`: the default blueprint; :mod:`~mlpfac.log.about`: its text panel
- :mod:`~mlpfac.log.compare`: saved runs opened in a viewer, several as one recording (``mlpfac view A B``)

No wall-clock time is recorded, so the same run gives the same decoded contents. The bytes of two
.rrd files still differ: rerun stamps every chunk and row with a time-based unique id.
"""

import os

# rerun's file sink logs its own write errors (and keeps going); mlpfac reads the file back instead
# (sinks.check_recording) and reports one line. Its log sink warns when it drops what it still
# held at a close that timed out: a stopped run discards its recording anyway, and a finished one
# whose recording cannot be closed fails with its own line. An explicit RUST_LOG is left alone.
os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd=off,re_sdk::recording_stream=off,re_sdk::log_sink=error")

from mlpfac.log.compare import view  # noqa: E402
from mlpfac.log.layout import blueprint  # noqa: E402
from mlpfac.log.recorder import (  # noqa: E402
    APPLICATION_ID,
    BATCH_ROWS,
    BATCH_SECONDS,
    STATUS_LEVEL,
    RerunSink,
    event_text,
)
from mlpfac.log.scene import PATH_POINT_STRIDE, PATH_STRIDE, POSE_STRIDE, driven_path  # noqa: E402
from mlpfac.log.schema import PATH_COLOR, REF_COLOR, ROBOT_COLOR, SCHEMA, WEIGHT_COLORS, Row  # noqa: E402
from mlpfac.log.series import Series, plan_series  # noqa: E402
from mlpfac.log.sinks import check_recording, make_sink, rerun_executable  # noqa: E402

__all__ = [
    "APPLICATION_ID",
    "BATCH_ROWS",
    "BATCH_SECONDS",
    "PATH_COLOR",
    "PATH_POINT_STRIDE",
    "PATH_STRIDE",
    "POSE_STRIDE",
    "REF_COLOR",
    "ROBOT_COLOR",
    "SCHEMA",
    "STATUS_LEVEL",
    "WEIGHT_COLORS",
    "RerunSink",
    "Row",
    "Series",
    "blueprint",
    "check_recording",
    "driven_path",
    "event_text",
    "make_sink",
    "plan_series",
    "rerun_executable",
    "view",
]
