"""Pure maths: map representation, BRDF, renderer, light sampling, exposure.

Nothing in this package imports Lightning, Hydra or Mitsuba.
"""
