"""The shipped scenarios: one TOML file each, read by mlpfac.scenario.parse through importlib.resources."""
