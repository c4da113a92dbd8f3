"""Motion concepts (paper §3.1): spline segmentation, anchor concepts, transition concepts."""
import warnings


def __getattr__(name):
    # refiner.concepts was a module before 0.2; its names now live in refiner.concepts.learning
    if name in ("MotionConcepts", "learn_concepts", "segment_dataset"):
        # imported on use: learning brings torch, which importing refiner.concepts.segmentation must not
        from refiner.concepts import learning

        warnings.warn(f"refiner.concepts.{name} moved to refiner.concepts.learning.{name}; the old path goes in 0.3.",
                      DeprecationWarning, stacklevel=2)
        return getattr(learning, name)
    raise AttributeError(f"module 'refiner.concepts' has no attribute {name!r}")
