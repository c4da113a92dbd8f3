"""Network machinery shared by every learned part: the estimator base class, building blocks, the training loop."""
