"""Refinement (paper §3.2): the default refiner (a learned motion model, :mod:`~refiner.refinement.motion_refiner`) and
the concepts method (recognition, anchor and transition refinement, :class:`~refiner.refinement.pipeline.Refiner`)."""
