"""jsss: differentiable subsurface scattering in JAX.

Subpackages follow the papers: :mod:`jsss.diffusion` (dipole, single scattering, BRDF,
multipole, oblique incidence, sampling), :mod:`jsss.layers` (Hankel transform, Kubelka-Munk
stacks), :mod:`jsss.gaussians` (sums of Gaussians and their closed-form fits),
:mod:`jsss.transport` (the Monte Carlo truth and the profiles exact to radiative transfer) and
:mod:`jsss.render`. The most used modules are re-exported here (``from jsss import dipole``).
Lengths in mm, coefficients in 1/mm.
"""

from . import fresnel, materials, numerics
from .diffusion import brdf, dipole, incidence, multipole, sampling, single_scattering
from .layers import hankel
from .transport import montecarlo
from . import diffusion, gaussians, layers, transport
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
    "diffusion",
    "dipole",
    "fresnel",
    "gaussians",
    "hankel",
    "incidence",
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
