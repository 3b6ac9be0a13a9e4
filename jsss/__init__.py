"""jsss: differentiable subsurface scattering in JAX.

Public modules: :mod:`jsss.dipole`, :mod:`jsss.single_scattering`, :mod:`jsss.brdf`,
:mod:`jsss.fresnel`, :mod:`jsss.materials`,
:mod:`jsss.multipole`, :mod:`jsss.hankel`, :mod:`jsss.layers`, :mod:`jsss.transport` (profiles exact to
radiative transfer), :mod:`jsss.montecarlo`. Lengths in mm, coefficients in 1/mm.
"""

from . import (
    brdf,
    dipole,
    fresnel,
    gaussians,
    hankel,
    layers,
    materials,
    montecarlo,
    multipole,
    numerics,
    sampling,
    single_scattering,
    transport,
)
from .medium import Medium as Medium
from .medium import reduced_albedo as reduced_albedo


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jsss")
    except PackageNotFoundError:  # a source tree that was not installed
        return "unknown"


__version__ = _version()

__all__ = [
    "Medium",
    "__version__",
    "brdf",
    "dipole",
    "fresnel",
    "gaussians",
    "hankel",
    "layers",
    "materials",
    "montecarlo",
    "multipole",
    "numerics",
    "reduced_albedo",
    "sampling",
    "single_scattering",
    "transport",
]
