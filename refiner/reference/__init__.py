"""Reference generators trained on HumanAct12, so the refiner can be measured on real generator output."""
