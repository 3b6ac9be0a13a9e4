"""jsss: differentiable subsurface scattering in JAX.

Subpackages follow the papers: :mod:`jsss.diffusion` (dipole, single scattering, BRDF,
multipole, oblique incidence, sampling), :mod:`jsss.layers` (Hankel transform, Kubelka-Munk
stacks), :mod:`jsss.gaussians` (sums of Gaussians and their closed-form fits),
:mod:`jsss.transport` (the Monte Carlo truth and the profiles exact to radiative transfer) and
:mod:`jsss.render`. The most used modules are re-exported here (``from jsss import dipole``).
Lengths in mm, coefficients in 1/mm.

Every name here is imported on first use (PEP 562): ``import jsss`` costs nothing, and a
command that needs only a light module (``jsss.render.passes`` for its ``--help``) does not
pay the 1.2 s of JAX, equinox and SciPy that importing them all did.
"""

from __future__ import annotations

import importlib
import importlib.util

# Each public name and the module it lives in (the attribute of that name, or the module itself).
_MODULES = {
    "brdf": ".diffusion.brdf",
    "diffusion": ".diffusion",
    "dipole": ".diffusion.dipole",
    "fresnel": ".fresnel",
    "gaussians": ".gaussians",
    "hankel": ".layers.hankel",
    "incidence": ".diffusion.incidence",
    "layers": ".layers",
    "materials": ".materials",
    "montecarlo": ".transport.montecarlo",
    "multipole": ".diffusion.multipole",
    "numerics": ".numerics",
    "sampling": ".diffusion.sampling",
    "single_scattering": ".diffusion.single_scattering",
    "transport": ".transport",
}
_NAMES = {"Medium": ".medium", "reduced_albedo": ".medium"}


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jsss")
    except PackageNotFoundError:  # a source tree that was not installed
        return "unknown"


def __getattr__(name: str):
    if name in _MODULES:
        value = importlib.import_module(_MODULES[name], __name__)
    elif name in _NAMES:
        value = getattr(importlib.import_module(_NAMES[name], __name__), name)
    elif name == "__version__":
        value = _version()
    elif importlib.util.find_spec(f"{__name__}.{name}") is not None:  # a submodule, as the eager imports bound them
        return importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # once: the next look-up does not come here
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


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
