"""Evaluation metrics (paper §6.2) as DDP-correct torchmetrics: per-map RMSE at full and
downscaled resolution, normal angular error, a fixed-configuration re-rendering error, the
base colour's saturation ratio and hue error, and the error near the flash highlight relative to
elsewhere.
Definitions in :mod:`brdfgan.metrics.svbrdf_metrics`.
"""

from brdfgan.metrics.svbrdf_metrics import (
    ALBEDO_SPACE,
    HOTSPOT_RADIUS_FRACTION,
    RMSE_MAPS,
    HotspotError,
    HueError,
    MapRMSE,
    NormalAngularError,
    RerenderError,
    SaturationRatio,
    SVBRDFMetrics,
    area_downscale,
    basecolor_hsv,
    check_hotspot_radius,
    compared_maps,
    downscaled_size,
    fixed_render_configs,
    hotspot_centres,
    hotspot_disk,
    hue_difference_deg,
    hue_error_deg,
    saturation_ratio,
    stored_photo_size,
)

__all__ = [
    "ALBEDO_SPACE",
    "HOTSPOT_RADIUS_FRACTION",
    "RMSE_MAPS",
    "HotspotError",
    "HueError",
    "MapRMSE",
    "NormalAngularError",
    "RerenderError",
    "SVBRDFMetrics",
    "SaturationRatio",
    "area_downscale",
    "basecolor_hsv",
    "check_hotspot_radius",
    "compared_maps",
    "downscaled_size",
    "fixed_render_configs",
    "hotspot_centres",
    "hotspot_disk",
    "hue_difference_deg",
    "hue_error_deg",
    "saturation_ratio",
    "stored_photo_size",
]
