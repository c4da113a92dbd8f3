"""The ``motion-refiner`` command line: one module per sub-command; the only code that prints.

The parser is :mod:`refiner.cli.main`. The sub-command handlers of the old ``refiner.commands`` module
(demo, refine, train-generator, and :func:`load_input`) are importable from here.
"""

from refiner.cli.demo import demo_arguments, demo_run
from refiner.cli.main import COMMANDS, main
from refiner.cli.refine import load_input, refine_arguments, refine_run
from refiner.cli.train_generator import train_generator_arguments, train_generator_run

__all__ = [
    "main",
    "COMMANDS",
    "demo_arguments",
    "demo_run",
    "refine_arguments",
    "refine_run",
    "train_generator_arguments",
    "train_generator_run",
    "load_input",
]
