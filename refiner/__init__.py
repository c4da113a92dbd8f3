"""motion-refiner: refine synthesized 3D human motion with unsupervised learned motion concepts."""
from __future__ import annotations

from refiner.core.motion import Motion, stack_motions, unstack_motions
from refiner.core.skeletons import Skeleton, get_skeleton, list_skeletons, register_skeleton
from refiner.refinement.refined_generator import RefinedGenerator

__all__ = [
    "Motion",
    "RefinedGenerator",
    "Refiner",
    "RefinementReport",
    "Skeleton",
    "__version__",
    "get_skeleton",
    "list_skeletons",
    "refine",
    "register_skeleton",
    "stack_motions",
    "unstack_motions",
]


_LAZY = {"refine": "refiner.refinement.pipeline", "Refiner": "refiner.refinement.pipeline", "RefinementReport": "refiner.refinement.pipeline"}


def __getattr__(name):
    # the pipeline imports torch and the networks: load it on first use so `import refiner` stays cheap
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("motion-refiner")
        except PackageNotFoundError:
            return "unknown"
    raise AttributeError(f"module 'refiner' has no attribute {name!r}")
