"""The ``motion-refiner`` command line: one module per sub-command; the only code that prints."""

from refiner.cli.main import COMMANDS, main

__all__ = ["main", "COMMANDS"]
