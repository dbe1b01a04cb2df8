"""mlpfac: multilayer-perceptron functional adaptive control of a wheeled mobile robot, tested on MuJoCo."""

__version__ = "0.1.0"
