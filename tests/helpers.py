"""Helpers shared by the tests: finite differences and quadrature on log grids."""

from __future__ import annotations

import numpy as np


def central_difference(f, x, *, rel_step=1e-6):
    """Central difference of scalar ``f`` at scalar ``x`` with a step relative to ``|x|``."""
    h = rel_step * max(abs(float(x)), 1e-3)
    return (float(f(x + h)) - float(f(x - h))) / (2 * h)


def radial_integral(values_fn, r_min, r_max, *, n=40001):
    """``2 pi int r f(r) dr`` on a log grid by Simpson's rule (substituting r = e^t).

    ``values_fn`` maps an array of radii (N,) to values (N, ...). The part below
    ``r_min`` is added as ``pi r_min^2 f(r_min)`` (f is flat there for the profiles).
    """
    from scipy.integrate import simpson

    t = np.linspace(np.log(r_min), np.log(r_max), n)
    r = np.exp(t)
    f = np.asarray(values_fn(r))
    weights = (2 * np.pi * r**2).reshape((-1,) + (1,) * (f.ndim - 1))
    core = simpson(weights * f, x=t, axis=0)
    return core + np.pi * r_min**2 * f[0]


def fresnel_reflectance_numpy(cos_i, eta):
    """Unpolarised Fresnel reflectance written out in NumPy, apart from ``jsss.fresnel`` (a truth for tests)."""
    cos_i = np.asarray(cos_i, float)
    sin_t2 = (1 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.maximum(1 - sin_t2, 0.0))
    rs = (cos_i - eta * cos_t) / np.maximum(cos_i + eta * cos_t, 1e-300)
    rp = (eta * cos_i - cos_t) / np.maximum(eta * cos_i + cos_t, 1e-300)
    return np.where(sin_t2 >= 1, 1.0, 0.5 * (rs**2 + rp**2))


def external_diffuse_transmittance(eta):
    """int_0^1 (1 - F(mu, eta)) 2 mu dmu by adaptive quadrature: diffuse light from outside that enters."""
    from scipy.integrate import quad

    lower = np.sqrt(max(0.0, 1 - eta**2))
    return quad(lambda mu: (1 - fresnel_reflectance_numpy(mu, eta)) * 2 * mu, lower, 1, epsabs=1e-13, limit=200)[0]
