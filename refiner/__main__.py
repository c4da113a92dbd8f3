"""``python -m refiner`` is ``motion-refiner``."""
import sys

from refiner.cli import main

sys.exit(main())
