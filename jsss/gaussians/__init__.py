"""Sums of Gaussians: representation, algebra, closed-form fits and the polynomial basis.

Public face of :mod:`jsss.gaussians.gaussian_sum` (the :class:`GaussianSum` type and its algebra),
:mod:`jsss.gaussians.pole_fit` (the empirical dipole/multipole fits, after d'Eon 2007 App. A) and
:mod:`jsss.gaussians.poly_gaussians` (polynomial-of-Gaussians arithmetic and Kubelka-Munk layers).
Iterative least-squares fits live in :mod:`fitting`.
"""

from .gaussian_sum import (
    GaussianSum as GaussianSum,
    add as add,
    convolve as convolve,
    evaluate as evaluate,
    gaussian as gaussian,
    reduce_to as reduce_to,
    relative_rms_error as relative_rms_error,
    scale as scale,
    second_moment as second_moment,
    total as total,
)
from .pole_fit import (
    VARIANCE_RATIOS as VARIANCE_RATIOS,
    derive_pole_weights as derive_pole_weights,
    empirical_dipole_fit as empirical_dipole_fit,
    empirical_multipole_fit as empirical_multipole_fit,
    pole_weight_curves as pole_weight_curves,
)
from .poly_gaussians import (
    PolyGaussian as PolyGaussian,
    geometric_series as geometric_series,
    layers_as_gaussians as layers_as_gaussians,
    poly_add as poly_add,
    poly_multiply as poly_multiply,
    poly_total as poly_total,
    to_gaussian_sum as to_gaussian_sum,
    to_poly as to_poly,
)
