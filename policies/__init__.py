"""The shipped policies: one .npz of weights each (mlpfac.control.policy), read through importlib.resources."""
