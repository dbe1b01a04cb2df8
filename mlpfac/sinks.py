"""The old name of :mod:`mlpfac.log.sinks`: the same module object, so patching one patches both."""

import sys

from mlpfac.log import sinks

sys.modules[__name__] = sinks
