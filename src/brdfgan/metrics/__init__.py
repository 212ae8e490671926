"""Evaluation metrics (paper §6.2) as DDP-correct torchmetrics: per-map RMSE at full and
downscaled resolution, normal angular error, and a fixed-configuration re-rendering error.
Definitions in :mod:`brdfgan.metrics.svbrdf_metrics`.
"""

from brdfgan.metrics.svbrdf_metrics import (
    ALBEDO_SPACE,
    RMSE_MAPS,
    MapRMSE,
    NormalAngularError,
    RerenderError,
    SVBRDFMetrics,
    area_downscale,
    compared_maps,
    downscaled_size,
    fixed_render_configs,
)

__all__ = [
    "ALBEDO_SPACE",
    "RMSE_MAPS",
    "MapRMSE",
    "NormalAngularError",
    "RerenderError",
    "SVBRDFMetrics",
    "area_downscale",
    "compared_maps",
    "downscaled_size",
    "fixed_render_configs",
]
