"""Physically based rendering of map sets with Mitsuba 3 (data generation, cross-checks).

Mitsuba is imported lazily, after :func:`select_variant` has pointed Dr.Jit at a usable LLVM.
"""
