r"""Fresnel reflection at a smooth dielectric boundary.

For the directional functions ``eta`` is the index of the medium behind the
boundary relative to the medium the light arrives in. For the diffuse quantities
(:func:`diffuse_fresnel_reflectance`, :func:`internal_reflection_parameter`) it
follows Jensen et al. 2001 sec. 2.1: the index of the scattering medium relative to
the medium outside (1.3 for skin against air).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .numerics import as_float_array, safe_sqrt

__all__ = [
    "diffuse_fresnel_reflectance",
    "diffuse_fresnel_transmittance",
    "exit_lobe",
    "fresnel_reflectance",
    "fresnel_transmittance",
    "internal_reflection_parameter",
    "refracted_cosine",
]


def refracted_cosine(cos_outside, eta):
    r"""Cosine of the refracted angle inside a medium of relative index ``eta``.

    Snell's law for light entering from outside (index 1) into index ``eta``:
    :math:`\cos\theta' = \sqrt{1 - (1 - \cos^2\theta)/\eta^2}`.

    Parameters
    ----------
    cos_outside : array_like
        Cosine of the angle to the normal outside, in [0, 1].
    eta : array_like
        Relative index inside / outside, > 0.

    Returns
    -------
    cos_inside : Array
        In [0, 1]; 0 beyond the critical angle (possible only for ``eta < 1``).
    """
    cos_outside = as_float_array(cos_outside)
    sin2 = (1 - cos_outside**2) / jnp.square(eta)
    return safe_sqrt(1 - sin2)


def fresnel_reflectance(cos_incident, eta):
    r"""Unpolarised Fresnel reflectance of a smooth boundary.

    Light arrives at angle :math:`\theta_i` (``cos_incident`` = :math:`\cos\theta_i`) in
    a medium of index :math:`n_1` and meets a medium of index :math:`n_2`, with
    ``eta`` :math:`= n_2 / n_1`. Returns the mean of the s and p reflectances; 1 under
    total internal reflection (``eta < 1`` past the critical angle).

    Parameters
    ----------
    cos_incident : array_like
        In [0, 1].
    eta : array_like
        Relative index :math:`n_2 / n_1`, > 0.

    Returns
    -------
    Fr : Array in [0, 1]
    """
    cos_i = as_float_array(cos_incident)
    eta = as_float_array(eta)
    cos_t = refracted_cosine(cos_i, eta)
    total_internal = (1 - cos_i**2) >= jnp.square(eta)
    # Double `where`: the denominators vanish only where both cosines do.
    rs_den = cos_i + eta * cos_t
    rp_den = eta * cos_i + cos_t
    ok = (rs_den > 0) & (rp_den > 0) & ~total_internal
    rs = (cos_i - eta * cos_t) / jnp.where(ok, rs_den, 1.0)
    rp = (eta * cos_i - cos_t) / jnp.where(ok, rp_den, 1.0)
    return jnp.where(ok, 0.5 * (rs**2 + rp**2), 1.0)


def fresnel_transmittance(cos_incident, eta):
    """``1 - fresnel_reflectance(cos_incident, eta)``: the energy transmitted."""
    return 1 - fresnel_reflectance(cos_incident, eta)


def diffuse_fresnel_reflectance(eta):
    r"""Average diffuse Fresnel reflectance :math:`F_{dr}` seen from inside a medium.

    Rational fits to :math:`F_{dr} = \int_{2\pi} F_r(\eta, n\cdot\omega)(n\cdot\omega)\,d\omega / \pi`
    for light inside a medium of index ``eta`` relative to outside:

    * ``eta >= 1`` (Jensen et al. 2001 sec. 2.1, after Egan & Hilgeman):
      :math:`F_{dr} = -1.440/\eta^2 + 0.710/\eta + 0.668 + 0.0636\,\eta`;
    * ``eta < 1`` (Egan & Hilgeman 1979, as used by Donner & Jensen 2005 between layers):
      :math:`F_{dr} = -0.4399 + 0.7099/\eta - 0.3319/\eta^2 + 0.0636/\eta^3`,
      lowered by 1e-4 so that the two fits join continuously at ``eta = 1`` (as
      published they give 0.0016 and 0.0017 there, a jump that breaks derivatives
      in ``eta``; the shift is far inside the fits' accuracy).

    The exact :math:`F_{dr}` has a kink at ``eta = 1``: total internal reflection
    adds about :math:`2(\eta - 1)` above it and nothing below. The derivative
    returned at exactly ``eta = 1`` is the right-hand one (the ``eta >= 1`` fit).

    Both are within 0.01 of the exact integral on [1, 2] and [0.6, 1]
    (``tests/jsss/test_fresnel.py`` checks this).

    Parameters
    ----------
    eta : array_like
        Relative index (medium / outside), > 0.
    """
    eta = as_float_array(eta)
    safe_eta = jnp.where(eta > 0, eta, 1.0)
    above = -1.440 / safe_eta**2 + 0.710 / safe_eta + 0.668 + 0.0636 * safe_eta
    below = -0.4400 + 0.7099 / safe_eta - 0.3319 / safe_eta**2 + 0.0636 / safe_eta**3
    return jnp.where(eta >= 1, above, below)


_GAUSS_LEGENDRE = np.polynomial.legendre.leggauss(32)


def diffuse_fresnel_transmittance(eta):
    r"""Mean Fresnel transmittance of diffuse light arriving from *outside*, :math:`1 - F_{dr,ext}`.

    .. math:: T_{dr}(\eta) = \int_{2\pi} F_t(\cos\theta_o, \eta)\,\cos\theta_o\,d\omega_o / \pi
                           = \int_0^1 F_t(\mu, \eta)\,2\mu\,d\mu,

    with :math:`\theta_o` the angle *outside* the medium. By reciprocity this is also the
    integral that turns an exit Fresnel lobe :math:`F_t(\cos\theta_o)` into exitance:
    radiance :math:`L = M F_t(\cos\theta_o) / (\pi T_{dr})` carries exactly :math:`M`.
    Snell's invariance of :math:`\eta^2\cos\theta\,d\omega` gives
    :math:`T_{dr} = \eta^2\,(1 - F_{dr})` with :math:`F_{dr}` the *internal* diffuse
    reflectance of :func:`diffuse_fresnel_reflectance`, so it is not :math:`1 - F_{dr}`
    (0.908 against 0.403 at ``eta = 1.5``).

    Computed exactly (not fitted): 32-point Gauss-Legendre quadrature in :math:`\mu`,
    on :math:`[\mu_c, 1]` where :math:`\mu_c = \sqrt{1 - \eta^2}` is the critical cosine
    for ``eta < 1`` (0 otherwise). Error below 1e-8 for ``eta >= 1`` and 1e-5 for
    ``eta`` in [0.6, 1) (``tests/jsss/test_fresnel.py``); differentiable in ``eta``.

    Parameters
    ----------
    eta : array_like
        Relative index (medium / outside), > 0.

    Returns
    -------
    Array of ``eta``'s shape, in (0, 1]; exactly 1 at ``eta = 1``.
    """
    eta = as_float_array(eta)
    nodes, weights = (jnp.asarray(a, eta.dtype) for a in _GAUSS_LEGENDRE)
    lower = safe_sqrt(jnp.maximum(1 - jnp.square(eta), 0.0))
    half = (1 - lower)[..., None] / 2
    mu = lower[..., None] + half * (nodes + 1)
    transmitted = fresnel_transmittance(mu, eta[..., None])
    return (transmitted * 2 * mu * weights * half).sum(-1)


def exit_lobe(cos_exit, eta):
    r"""Radiance per unit exitance leaving toward ``cos_exit`` under the diffusion exit law [1/sr].

    .. math:: L / M = \frac{F_t(\cos\theta_o, \eta)}{\pi\,T_{dr}(\eta)},

    the Fresnel-transmitted share of a radiance that is isotropic over the inside hemisphere,
    normalised so that :math:`\int L\cos\theta_o\,d\omega_o = M` exactly
    (:func:`diffuse_fresnel_transmittance`). The renderer spreads exitance with it, and
    :func:`jsss.diffusion.dipole.radiance` is the dipole's exitance times it. Transport is not this
    simple: near the source (and at low albedo) light leaves at grazing angles, so a camera
    looking down sees less (:func:`jsss.transport.radiance`).

    Parameters
    ----------
    cos_exit : array_like
        Cosine of the exit direction *outside*, in [0, 1] (clipped).
    eta : array_like
        Relative index (medium / outside), > 0; broadcasts with ``cos_exit``.
    """
    cos = jnp.clip(as_float_array(cos_exit), 0.0, 1.0)
    return fresnel_transmittance(cos, eta) / (jnp.pi * diffuse_fresnel_transmittance(eta))


def internal_reflection_parameter(eta):
    r""":math:`A = (1 + F_{dr}) / (1 - F_{dr})`, the boundary's internal reflection (Jensen eq. 4)."""
    fdr = diffuse_fresnel_reflectance(eta)
    return (1 + fdr) / (1 - fdr)
