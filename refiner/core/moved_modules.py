"""Import paths of 0.1 (one flat ``refiner/`` folder) that keep working, with a DeprecationWarning, until 0.3.

``import refiner.pipeline`` gives the module ``refiner.refinement.pipeline`` itself (not a copy), so
``from refiner.pipeline import Refiner`` and monkeypatching through the old name act on the real module.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

__all__ = ["MOVED", "install"]

#: Old module name under ``refiner.`` -> its module now, under ``refiner.``.
MOVED = {
    "anchor_refinement": "refinement.anchor_refinement",
    "anchors": "concepts.anchors",
    "baselines": "evaluation.baselines",
    "bench": "evaluation.bench",
    "bench_flaws": "evaluation.bench_flaws",
    "bench_refiner": "evaluation.bench_refiner",
    "bench_samples": "evaluation.bench_samples",
    "bench_skeletons": "evaluation.bench_skeletons",
    "bvh": "io.bvh",
    "commands": "cli",
    "components": "nn.components",
    "converted_refinement": "refinement.converted_refinement",
    "data_sources": "io.data_sources",
    "datasets": "io.datasets",
    "demo": "cli.demo",
    "doctor": "cli.doctor",
    "encoders": "refinement.encoders",
    "evaluator_weights": "evaluation.evaluator_weights",
    "evaluators": "evaluation.evaluators",
    "flaw_classifier": "refinement.flaw_classifier",
    "flaw_features": "refinement.flaw_features",
    "flaw_networks": "refinement.flaw_networks",
    "flaw_training": "refinement.flaw_training",
    "flaws": "evaluation.flaws",
    "foot_contact": "core.contact",
    "generators": "refinement.refined_generator",
    "joints_dataset": "io.joints_dataset",
    "learned_pipeline": "refinement.learned_pipeline",
    "learned_refinement": "refinement.learned_refinement",
    "learned_training": "refinement.train_learned",
    "manifest": "core.manifest",
    "metrics": "evaluation.metrics",
    "motion": "core.motion",
    "output_kind": "core.output_kind",
    "physics": "evaluation.physics",
    "pipeline": "refinement.pipeline",
    "recognition": "refinement.anchor_recognition",
    "reference_generators": "reference",
    "repair_candidates": "refinement.repair_candidates",
    "safe_pickle": "core.safe_pickle",
    "segmentation": "concepts.segmentation",
    "serialization": "core.serialization",
    "skeleton_conversion": "core.skeleton_conversion",
    "skeletons": "core.skeletons",
    "splines": "concepts.splines",
    "trainer": "refinement.train_refiner",
    "training": "nn.training",
    "training_flaws": "refinement.training_flaws",
    "transition_refinement": "refinement.transition_refinement",
    "transitions": "concepts.transitions",
    "validation": "core.validation",
    "viz": "io.viz",
}


class _MovedLoader(importlib.abc.Loader):
    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        return None

    def exec_module(self, module) -> None:
        warnings.warn(f"{module.__name__} moved to {self.target}; the old path goes in 0.3.", DeprecationWarning,
                      stacklevel=2)
        # the import system returns what sys.modules holds after exec: the real module, not this stand-in
        sys.modules[module.__name__] = importlib.import_module(self.target)


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        prefix, _, name = fullname.partition(".")
        if prefix == "refiner" and name in MOVED:
            return importlib.util.spec_from_loader(fullname, _MovedLoader(f"refiner.{MOVED[name]}"))
        return None


def install() -> None:
    """Put the finder of moved modules on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
