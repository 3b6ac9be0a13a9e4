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
