"""The networks of the refiner, one ``nn.Module`` per concept."""
