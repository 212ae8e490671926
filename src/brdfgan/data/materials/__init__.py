"""Procedural material library: families of parametric SVBRDF generators (paper §5)."""
