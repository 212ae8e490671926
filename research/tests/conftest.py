"""The research tier's fixtures: the product tests' own (tests/conftest.py), shared rather than copied."""

from tests.conftest import tiny_data

__all__ = ["tiny_data"]
