"""``python -m gaitlib.cli``: the ``gaitlib`` command (how ``torchrun -m gaitlib.cli train ...`` starts it)."""

from gaitlib.cli import main

main()
