"""fitting: iterative fits of jsss models to data (Gaussian sums, medium parameters)."""

from .render import RenderFit as RenderFit, fit_render as fit_render
from .gaussians import (
    GaussianFit as GaussianFit,
    fit_gaussians as fit_gaussians,
    fit_gaussians_to_medium as fit_gaussians_to_medium,
    jensen2001_profiles as jensen2001_profiles,
    radial_grid as radial_grid,
)

__all__ = ["GaussianFit", "RenderFit", "fit_gaussians", "fit_gaussians_to_medium", "fit_render", "jensen2001_profiles",
           "radial_grid"]
