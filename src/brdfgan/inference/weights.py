"""Moved to :mod:`brdfgan.runs` (one module loads every network); kept while callers move."""

from brdfgan.runs import WeightsError, load_checkpoint_generator, load_generator, load_weights, save_weights

__all__ = ["WeightsError", "load_checkpoint_generator", "load_generator", "load_weights", "save_weights"]
