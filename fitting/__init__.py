"""fitting: iterative fits of jsss models to data (Gaussian sums, medium parameters, a material from a photo)
and the statistics they share (:mod:`fitting.statistics`).

The names below load their module on first use: ``fit-params`` needs only
:mod:`fitting.medium`, and importing the renderer behind :func:`fit_render` cost it 0.7 s.
"""

import importlib

_HOME = {
    "RenderFit": "render",
    "fit_render": "render",
    "GaussianFit": "gaussians",
    "fit_gaussians": "gaussians",
    "fit_gaussians_to_medium": "gaussians",
    "jensen2001_profiles": "gaussians",
    "radial_grid": "gaussians",
    "MediumFit": "medium",
    "fit_medium": "medium",
    "RenderFitError": "render",
    "AlbedoMapFit": "albedo_map",
    "AlbedoMapError": "albedo_map",
    "fit_albedo_map": "albedo_map",
}

__all__ = sorted(_HOME)


def __getattr__(name):
    if name in _HOME:
        value = getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
        globals()[name] = value  # once
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
