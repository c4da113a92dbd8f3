"""Evaluation: pretrained recognisers, distribution and physical metrics, seeded flaws, baselines, bench suites."""
