"""The shipped scenarios: one TOML file each, read by mlpfac.scenario through importlib.resources."""
