"""gaitlib's measurements beside the library: the timing and fault-injection scripts (each run as
``python benchmarks/NAME.py``) and :mod:`benchmarks.results`, the generator of the results pages' tables."""
