"""Pure maths: shape checks, map representation, BRDF, renderer, rendering-loss sampling, exposure,
lighting (equirect environments and the sun, the preview sky and its importance sampling, relighting).

Nothing in this package imports Lightning, Hydra or Mitsuba.
"""
