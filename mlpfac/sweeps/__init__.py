"""The sweep engine behind ``mlpfac sweep`` and ``mlpfac compare``; see :mod:`mlpfac.sweep`."""
