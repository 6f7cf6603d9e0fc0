"""legoh: LEGO-H humanoid hiking on MuJoCo and TorchRL."""

__version__ = "0.1.0"
