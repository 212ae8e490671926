"""Evaluation: run generators over a test split, metric tables, bar charts, qualitative grids."""
