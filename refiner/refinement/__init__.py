"""Refinement (paper §3.2): recognition, anchor and transition refinement, the learned steps, the Refiner."""
