"""Evaluation: pretrained recognisers, distribution and physical metrics, seeded flaws, baselines, bench suites, a
refined clip's summary figure."""
