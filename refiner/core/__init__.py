"""Core data types and pure helpers: motion, skeletons, validation, serialization, manifests, contact, signals.

Imports nothing else of the package: everything else builds on it."""
