"""A run's folder: its files written whole, its metrics (``metrics.json``), the recording written after the run."""
