"""Corpus-scale refinement on Ray Data (the optional extra ``motion-refiner[ray]``): many shards, many workers.

:func:`refine_corpus` (``motion-refiner refine-corpus``) refines every ``.npy``/``.npz`` shard of a folder or glob
with the default refiner, one output and one JSON-lines report per shard, resumable. Importing this package does not
import Ray; a run does, and says how to install it where it is missing.
"""
from refiner.corpus.engine import INSTALL_HINT, ClipRefiner, CorpusSummary, corpus_settings, refine_corpus, require_ray
from refiner.corpus.shards import find_shards, is_complete, report_path

__all__ = ["ClipRefiner", "CorpusSummary", "INSTALL_HINT", "corpus_settings", "find_shards", "is_complete", "refine_corpus",
           "report_path", "require_ray"]
