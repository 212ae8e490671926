"""brdfgan: single flash photograph → SVBRDF maps (base color, normal, roughness, metallic)."""

__version__ = "0.1.0"
