"""Synthetic training data: procedural materials, capture simulation, shards, loading."""
