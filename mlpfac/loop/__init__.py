"""The closed loop: the plant and the controller built from a scenario, stepped for one run or a batch of seeds, into a :class:`~mlpfac.loop.record.RunRecord`."""
