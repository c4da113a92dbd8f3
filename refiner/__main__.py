"""``python -m refiner`` is ``motion-refiner``."""
import sys

from refiner.cli.main import main

sys.exit(main())
