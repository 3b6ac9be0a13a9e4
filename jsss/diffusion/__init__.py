"""Diffusion and single scattering of a homogeneous medium under a flat boundary.

Jensen et al. 2001 (:mod:`.dipole`, :mod:`.single_scattering`, :mod:`.brdf`), the
multipole of a finite slab after Donner & Jensen 2005 and d'Eon et al. 2007 sec. 3
(:mod:`.multipole`), exact importance sampling of the dipole after Mertens et al. 2003
(:mod:`.sampling`), and what the half space returns at oblique incidence, at which angle and
how far from where the light was last scattered, from Chandrasekhar's H function
(:mod:`.incidence`, :mod:`.exit_law`, :mod:`.lateral_step`). Lengths in mm, coefficients in 1/mm.
"""

from . import brdf, dipole, exit_law, incidence, lateral_step, multipole, sampling, single_scattering

__all__ = ["brdf", "dipole", "exit_law", "incidence", "lateral_step", "multipole", "sampling", "single_scattering"]
