"""Monte Carlo sweeps behind ``mlpfac sweep``, ``mlpfac compare``, :func:`mlpfac.sweep` and ``mlpfac check``: the plan, the workers, the run folders and their tables (:mod:`mlpfac.sweeps.engine`)."""
