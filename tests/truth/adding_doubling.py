"""Adding-doubling (iadpython) with its angular quadrature computed stably: the truth for totals.

A phase function as peaked as g = 0.9 (iadpython applies delta-M) needs many angles: at reduced
albedo 0.02 the diffuse total with 32 quadrature points (at eta > 1, 16 Gauss points below the
critical angle and 16 Radau points above it) is 1.0 % off the converged value at eta 1.3-1.5
and 1.9 % at eta 1.6, where 96, 128 and 192 points agree to 0.01 % (measured 2026-12-06).
Those 32 points had been the truth of the transport tables' low-albedo checks, and their error
had been read as the tables' (issue 37: "1.8 % at g 0.9").

More points need a stable rule. iadpython builds its Radau weights from
``scipy.special.legendre(n - 1).deriv()``, a polynomial in the power basis whose coefficients
lose precision as n grows: against closed-form moments its weights are 2.6e-6 off at 24
points, 3 % at 32 and meaningless past 40 (iadpython 0.5.3), and at eta 1 it uses Radau over all
points. :func:`gauss_radau` takes nodes and weights from the three-term recurrence
(``scipy.special.eval_legendre``) instead: exact to 1e-12 on polynomials of degree 2n - 2 up
to n = 128, and :func:`slab_rt` runs iadpython with it.
"""

from __future__ import annotations

from unittest import mock

import numpy as np
import scipy.optimize
import scipy.special


def gauss_radau(n, a=-1.0, b=1.0):
    """Gauss-Radau quadrature on [a, b] with the upper end b a node, as iadpython's ``radau``.

    Nodes: -1 and the roots of (P_{n-1} + P_n) / (1 + x), bracketed by the roots of P_n;
    weights 2 / n^2 at -1 and (1 - x) / (n P_{n-1}(x))^2 elsewhere (Abramowitz & Stegun
    25.4.31), all from the stable recurrence. Returned in iadpython's order (ascending, b last).
    """
    nodes = np.empty(n)
    weights = np.empty(n)
    nodes[0] = -1.0
    brackets = scipy.special.roots_legendre(n)[0]

    def radau_polynomial(x):
        return scipy.special.eval_legendre(n - 1, x) + scipy.special.eval_legendre(n, x)

    for i in range(n - 1):
        nodes[i + 1] = scipy.optimize.brentq(radau_polynomial, brackets[i], brackets[i + 1], xtol=1e-15, rtol=1e-15)
    weights[0] = 2.0 / n**2
    weights[1:] = (1 - nodes[1:]) / (n * scipy.special.eval_legendre(n - 1, nodes[1:])) ** 2
    nodes = 0.5 * (a - b) * nodes + 0.5 * (b + a)
    weights = 0.5 * (b - a) * weights
    return np.flip(nodes), np.flip(weights)


def quadrature_points(g):
    """Points that converge the totals to 0.01 %: 64 (g <= 0.5), 96 for a peaked phase function
    (at g = 0.9 and reduced albedo 0.02-0.1: 96, 128 and 192 points agree to 0.01 %, 64 to 0.04 %)."""
    return 96 if g > 0.5 else 64


def slab_rt(albedo, optical_thickness, g, eta, quad_pts=None):
    """iadpython's (UR1, UT1, URU, UTU) of a slab in air (no slides), with the stable quadrature.

    UR1 is the total reflectance of a collimated normal beam, specular reflection F(0) included.
    """
    import iadpython

    sample = iadpython.Sample(a=albedo, b=optical_thickness, g=g, n=eta, n_above=1.0, n_below=1.0,
                              quad_pts=quad_pts or quadrature_points(g))
    with mock.patch.object(iadpython.quadrature, "radau", gauss_radau):
        return sample.rt()
