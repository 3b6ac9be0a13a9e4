"""Diffusion and single scattering of a homogeneous medium under a flat boundary.

Jensen et al. 2001 (:mod:`.dipole`, :mod:`.single_scattering`, :mod:`.brdf`), the
multipole of a finite slab after Donner & Jensen 2005 and d'Eon et al. 2007 sec. 3
(:mod:`.multipole`), exact importance sampling of the dipole after Mertens et al. 2003
(:mod:`.sampling`), and what the half space returns at oblique incidence, Chandrasekhar's H
function (:mod:`.incidence`). Lengths in mm, coefficients in 1/mm.
"""

from . import brdf, dipole, incidence, multipole, sampling, single_scattering

__all__ = ["brdf", "dipole", "incidence", "multipole", "sampling", "single_scattering"]
