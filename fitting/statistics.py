r"""What a least-squares fit reports about its estimate: reduced chi-square, covariance, standard errors.

For whitened residuals :math:`r(\theta)` (each divided by its standard error) with Jacobian
:math:`J` at the solution, :math:`m` residuals and :math:`n` parameters:

* :func:`reduced_chi2` -- :math:`\chi^2/\nu = r^T r / (m - n)`, about 1 when the model and the
  noise model both fit;
* :func:`error_scale` -- :math:`s^2 = \max(1, \chi^2/\nu)`: a model that cannot fit the data
  (:math:`\chi^2/\nu > 1`) widens its errors rather than claiming noise-level precision, and
  one below 1 says the noise model overstates the scatter, not that the estimate is known
  better than that noise;
* :func:`covariance` -- :math:`s^2 (J^T J)^{-1}` on the directions the data see, and the
  directions they do not (returned apart rather than dropped);
* :func:`standard_errors` -- the delta method: a quantity :math:`f(\theta)` with gradient
  :math:`g` has :math:`\sigma_f^2 = g^T C g`, infinite when it moves along an unseen direction.

Used by :func:`fitting.render.fit_render` (all four) and :func:`fitting.medium.fit_medium`
(the first two, in JAX inside its vmapped solve; its covariance is a pseudo-inverse with the
reference's scale error added, see there). :func:`reduced_chi2` and :func:`error_scale` take
NumPy or JAX values alike.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["POOR_FIT_CHI2", "covariance", "error_scale", "reduced_chi2", "standard_errors"]

# A chi^2/dof above this is more than the noise explains: the fit is called poor
# (measure.checks.fit_quality) and fit_medium first solves it again from every start.
POOR_FIT_CHI2 = 4.0
NULL_EIGENVALUE = 1e-12  # eigenvalues of J^T J below this share of the largest are directions the data do not see


def _is_jax(*values) -> bool:
    return any(isinstance(v, jax.Array) for v in values)


def reduced_chi2(sum_of_squares, m, n):
    r""":math:`\chi^2/\nu`: ``sum_of_squares`` of the whitened residuals over ``m - n`` degrees of
    freedom (at least 1), for ``m`` residuals and ``n`` parameters."""
    if _is_jax(sum_of_squares, m, n):
        return sum_of_squares / jnp.maximum(m - n, 1)
    return float(sum_of_squares) / max(m - n, 1)


def error_scale(chi2_reduced):
    r""":math:`s^2 = \max(1, \chi^2/\nu)`, the factor on :math:`(J^T J)^{-1}`: errors widen for a
    model that cannot fit its data and never shrink below the noise model's."""
    if _is_jax(chi2_reduced):
        return jnp.maximum(chi2_reduced, 1.0)
    return max(1.0, float(chi2_reduced))


def covariance(J, scale):
    """``scale (J^T J)^-1`` on the directions the data see, and the directions they do not.

    A direction along which the residuals do not change (an eigenvalue of J^T J below
    ``NULL_EIGENVALUE`` of the largest: Lambert's image is the same for sigma_a and sigma_s'
    scaled together) has no finite variance. A pseudo-inverse would silently drop it and
    report small errors for every parameter it involves, so it is returned as ``null``
    (columns) instead.

    Parameters
    ----------
    J : ndarray (m, n), the Jacobian of the whitened residuals at the estimate
    scale : float, :func:`error_scale`

    Returns
    -------
    covariance : ndarray (n, n); null : ndarray (n, k), the k unseen directions
    """
    H = np.asarray(J).T @ np.asarray(J)
    w, V = np.linalg.eigh(H)
    seen = w > max(w.max(), 1e-300) * NULL_EIGENVALUE
    return (V[:, seen] / w[seen]) @ V[:, seen].T * scale, V[:, ~seen]


def standard_errors(gradients, covariance, null):
    """Standard errors of quantities with ``gradients`` (rows, (q, n)) in the parameters (the
    delta method): infinite for a quantity that moves along a direction in ``null``."""
    gradients = np.atleast_2d(gradients)
    errors = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", gradients, covariance, gradients), 0, None))
    if null.shape[1]:
        leak = np.abs(gradients @ null).max(1) > 1e-6 * np.maximum(np.abs(gradients).max(1), 1e-300)
        errors = np.where(leak, np.inf, errors)
    return errors
