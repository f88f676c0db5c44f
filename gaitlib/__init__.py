"""gaitlib: a library of independently trained quadruped gaits and robust switching between them."""

__all__ = ["__version__"]

__version__ = "0.3.0"
