r"""Recover :math:`\sigma_a` and :math:`\sigma_s'` per channel from a measured radial profile.

Weighted least squares: each radial bin contributes :math:`(R_{model}(r_i) - R_i) / s_i`, with
:math:`s_i` the bin's standard error, and the measured total diffuse reflectance adds
:math:`(R_d^{model} - R_d) / s_{R_d}`, the constraint Jensen et al. use to remove the
ill-conditioning of the profile alone. Jensen et al. fit the profile's logarithm, and so did
this module until 2026-12-05; the two agree where a bin's relative error is small, but where it
nears 1 (the far bins of a dark channel) the log residual :math:`\ln(R_{model}/R_i)\,R_i/s_i`
grows without bound as noise pushes :math:`R_i` up, and bins that noise took to 0 or below had
to be dropped, which biases the tail upward. On ketchup's blue (R_d 0.0015, 1e5 photo-electrons
per unit) that gave chi^2/dof 6.7 at the estimate and sigma_a 3.1 % low; the linear residual,
the Gaussian likelihood of the bin means, gives chi^2/dof 0.79 and 0.7 % (0.96 and 0.1 % with
the tables' early part). Parameters are :math:`\ln\sigma_a, \ln\sigma_s'` (so both stay
positive), solved with optimistix's Gauss-Newton, all channels in one jitted call.
The start is the best of a scan of mean free paths and albedos (only evaluated): one solve
from a good start, not many solves that each run until the slowest is done (7 starts cost 7
times one). A channel that does not converge so is solved again by Levenberg-Marquardt from
7 spread starts. Standard errors come from the
Jacobian at the solution, :math:`\mathrm{cov} = s^2 (J^T J)^{-1}` with
:math:`s^2 = \max(1, \chi^2/(m - 2))` (:mod:`fitting.statistics`; the inverse is a
pseudo-inverse here, and a parameter the data do not feel is caught by ``converged``).

With ``"transport"`` the tables' own Monte Carlo noise is added: a model error, the same for
every image fitted with those tables, that the residuals cannot show (it is smooth in r and
the parameters absorb it). Each table cell c is an independent tally with relative error
:math:`\sigma_c` from the tables themselves (:func:`jsss.transport.profiles.noise_slice`:
:math:`\mathrm{Var}\,T = (T(2a')/A - T(a')^2)/N`); moving its log value by
:math:`\sigma_c\xi_c` (all absorption nodes alike) moves every radius that reads it, through
the interpolation, the beam, the bins and the total, so bins sharing a cell are correlated.
The fit's linear response :math:`\delta\theta = -(J^TJ)^{+}J^T\,\delta r` gives
:math:`\mathrm{cov} \mathrel{+}= G G^T` with :math:`G = -(J^TJ)^{+}J^T\,\partial r/\partial\xi`
(forward differentiation over the 73 radial cells of each of the one or two exit-angle bins
read). It is not scaled by :math:`s^2`: it is not the data's noise. Its share is reported
apart (``sigma_a_table_err``, ``sigma_s_prime_table_err``).

The forward model is a parameter. ``"dipole"`` is the dipole profile convolved with the
Gaussian beam (of standard deviation ``beam_sigma`` mm, from the reference image) through
the exact dipole spectrum and one inverse Hankel transform, and averaged over the same pixels
as each bin, so the finite beam and the binning do not bias the fit. The dipole itself is
biased near the source on real materials (diffusion theory). ``"transport"`` is
:func:`jsss.transport.profile`, exact to radiative transfer up to its tables' Monte Carlo
noise (g given by the caller), taken to the same spectrum by the grid's forward Hankel
transform; everything after the spectrum is shared.

What is measured is a parameter too: exitance (a tally of the light leaving), or what a
camera records, radiance toward it (``view_cos``; see :func:`fit_medium`). Near the source
the two differ by 20-40 % under transport (light leaves at grazing angles there), so a
camera's image fitted as exitance is biased even with an exact profile.
"""

from __future__ import annotations

from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import scipy.sparse

from jsss import transport
from jsss.transport import profiles
from jsss.diffusion import dipole
from jsss.layers import hankel
from fitting.programs import reusable_program
from fitting.statistics import POOR_FIT_CHI2, error_scale, reduced_chi2
from jsss.beam import observable
from jsss.medium import Medium
from jsss.numerics import warn_if_low_precision

__all__ = ["MODELS", "MediumFit", "fit_medium"]

MODELS = ("dipole", "transport")


class MediumFit(eqx.Module):
    """Result of :func:`fit_medium`; arrays have the channel shape ``C``.

    Attributes
    ----------
    medium : Medium
        The estimate.
    sigma_a_err, sigma_s_prime_err : Array [1/mm]
        One-sigma standard errors: s^2 (J^T J)^-1 with s^2 = max(1, chi^2/dof), plus the reference's scale error,
        plus (``model="transport"``) the tables' own Monte Carlo noise.
    total_reflectance : Array
        The model's total diffuse reflectance (whole plane) at the estimate.
    rel_residual : Array
        RMS of the relative residuals of the profile bins, :math:`(R_{model} - R)/R`.
    chi2_reduced : Array
        :math:`\\chi^2/(m - 2)` of the whitened residuals (about 1 for a good fit): the data's
        noise alone. It sets the errors' :math:`s^2`.
    chi2_reduced_tables : Array
        The same with the tables' own noise in the residuals' covariance,
        :math:`r^T (I + D D^T)^{-1} r/(m - 2)` with :math:`D` the whitened residuals' response to
        the table cells (module docstring); ``chi2_reduced`` for the dipole. What the fit's
        quality is judged by: an image whose noise is below the tables' shows their noise as a
        misfit that no parameter can remove.
    n_iterations : Array
    converged : Array of bool
        The solver met its tolerances *and* the estimate is determined: finite, with each
        standard error smaller than its parameter, and each parameter felt by the data (a
        factor e in it moves the whitened residuals by more than one): a parameter that ran
        away, to infinity or to 0, is not converged.
    sigma_a_table_err, sigma_s_prime_table_err : Array [1/mm]
        The share of the tables' Monte Carlo noise in the errors above (added in quadrature:
        the data's share is ``sqrt(err**2 - table_err**2)``); 0 for the dipole.
    model_bins : Array ``(n_bins, C)`` [1/mm^2]
        The model at the estimate in each bin of ``profile`` (beam and pixels as fitted): the
        expectation a noise model can be evaluated at (:func:`measure.pipeline.fit_measurement`).
    """

    medium: Medium
    sigma_a_err: jax.Array
    sigma_s_prime_err: jax.Array
    total_reflectance: jax.Array
    rel_residual: jax.Array
    chi2_reduced: jax.Array
    n_iterations: jax.Array
    converged: jax.Array
    sigma_a_table_err: jax.Array | None = None
    sigma_s_prime_table_err: jax.Array | None = None
    model_bins: jax.Array | None = None
    chi2_reduced_tables: jax.Array | None = None


def _interpolation_rows(grid_r, radii, rows, n_rows, scale):
    """Sparse-as-dense matrix (n_rows, M): row ``rows[j]`` gets ``scale[j]`` times the linear
    interpolation weights (in log r) of ``radii[j]`` on ``grid_r``. NumPy, built once per fit."""
    log_grid = np.log(grid_r)
    t = np.log(np.clip(radii, grid_r[0], grid_r[-1]))
    step = np.diff(log_grid)
    if np.allclose(step, step[0], rtol=1e-9, atol=0):  # log-uniform (hankel_grid): arithmetic, not a search
        j = np.clip(np.floor((t - log_grid[0]) / step[0]).astype(int), 0, grid_r.size - 2)
    else:
        j = np.clip(np.searchsorted(log_grid, t) - 1, 0, grid_r.size - 2)
    frac = (t - log_grid[j]) / (log_grid[j + 1] - log_grid[j])
    rows = np.broadcast_to(rows, t.shape)
    scale = np.broadcast_to(scale, t.shape)
    flat = np.concatenate([rows * grid_r.size + j, rows * grid_r.size + j + 1])  # bincount: 10x np.add.at
    weights = np.concatenate([scale * (1 - frac), scale * frac])
    return np.bincount(flat, weights, minlength=n_rows * grid_r.size).reshape(n_rows, grid_r.size)


def _model(params, args):
    """Bin means of the beam-convolved model and the model's total over the field of view.

    Everything between the model's values (a spectrum, or a profile on the transform grid)
    and the bins is linear and fixed for one measurement (beam, Hankel transforms,
    interpolation to each pixel, averaging over the bin), so it is one precomputed matrix:
    the model costs its values and a mat-vec.
    """
    log_sa, log_ss = params
    (model, g, view_cos), eta, fixed, k, grid_r, bins_operator, total_operator = args
    medium = Medium(jnp.exp(log_sa), jnp.exp(log_ss), eta)
    values, plane_total = observable(model, g, view_cos, medium, k, grid_r, fixed)
    total = plane_total if total_operator is None else total_operator @ values
    return bins_operator @ values, total


def _residuals(params, args):
    model_args, measured, inv_err, total, inv_total_err = args
    binned, model_total = _model(params, model_args)
    profile_part = (binned - measured) * inv_err
    total_part = (model_total - total) * inv_total_err
    return jnp.concatenate([profile_part, total_part[None]])


# Console scripts keep this traced across processes (its tracing is 4-6 s of a command's start).
@reusable_program(static_argnames=("max_steps", "model", "n_starts", "multistart"))
@partial(jax.jit, static_argnames=("max_steps", "model", "n_starts", "multistart"))
def _fit_channels(measured, stderr, totals, total_errs, scale_errs, eta, fixed, noise, k, grid_r, bins_operator,
                  total_operator, *, max_steps, rtol, atol, model, n_starts, multistart):
    # From a scanned start, Gauss-Newton takes 6-16 steps where Levenberg-Marquardt took 20-90
    # (its trust region grows slowly), to the same estimate (within 1e-9 on 13 of 16 transport
    # images; 0.2-0.5 % on three ketchup images whose chi^2/dof is 6-68). Levenberg-Marquardt
    # stays for the multistart retry, whose far starts need its damping.
    solver = (optx.LevenbergMarquardt if multistart else optx.GaussNewton)(rtol=rtol, atol=atol)

    def one(meas, err, total, total_err, scale_err, eta_c, fixed_c, noise_c):
        usable = err > 0
        inv_err = jnp.where(usable, 1.0 / jnp.where(usable, err, 1.0), 0.0)
        inv_rel_err = meas * inv_err
        inv_total_err = jnp.where(total_err > 0, 1.0 / jnp.where(total_err > 0, total_err, 1.0), 0.0)
        args = ((model, eta_c, fixed_c, k, grid_r, bins_operator, total_operator), meas, inv_err, total,
                inv_total_err)
        loss_of = lambda p: jnp.sum(_residuals(p, args) ** 2)  # noqa: E731

        def solve(start):
            sol = optx.least_squares(_residuals, solver, start, args, max_steps=max_steps, throw=False)
            loss = loss_of(sol.value)
            return sol.value, jnp.where(jnp.isfinite(loss), loss, jnp.inf), sol.stats["num_steps"], \
                sol.result == optx.RESULTS.successful

        candidates = _starting_points(total, eta_c, n_starts, scan=not multistart)
        if multistart:  # every start solved; lanes run until the slowest is done
            values, losses, steps, ok = jax.vmap(solve)(candidates)
            best = jnp.argmin(losses)
            params = jax.tree_util.tree_map(lambda x: x[best], values)
            loss, steps, ok = losses[best], steps[best], ok[best]
        else:  # the candidates are only evaluated; one solve from the best of them
            scanned = jax.vmap(loss_of)(candidates)
            best = jnp.argmin(jnp.where(jnp.isfinite(scanned), scanned, jnp.inf))
            params, loss, steps, ok = solve(jax.tree_util.tree_map(lambda x: x[best], candidates))
        jac = jax.jacfwd(lambda p: _residuals((p[0], p[1]), args))(jnp.stack(params))
        m = jnp.sum(usable) + (inv_total_err > 0)
        chi2_red = reduced_chi2(loss, m, 2)
        normal_inverse = jnp.linalg.pinv(jac.T @ jac)
        # s^2 = max(1, chi^2/dof) (fitting.statistics, as fit_render): a chi^2/dof below 1 says the pooled noise model
        # overstates the bins' scatter, not that the estimate is better known than that noise.
        # What the residuals cannot show still moves the estimate: the transport tables' own
        # Monte Carlo noise is smooth in r and is absorbed into the parameters. Scaling the errors
        # down by chi^2/dof (0.34-0.69 on walk images) made |z| reach 3.1 on images where it is 2.4.
        cov = normal_inverse * error_scale(chi2_red)
        # A calibration scale common to every bin and the total (the reference's sum) is
        # not in the per-bin errors: propagate it. Scaling the data by e^s shifts each log
        # residual by -s * inv_rel_err and the total residual by -s * total * inv_total_err.
        d_res_d_scale = -jnp.concatenate([inv_rel_err, (total * inv_total_err)[None]])
        d_params_d_scale = -normal_inverse @ (jac.T @ d_res_d_scale)
        cov = cov + jnp.outer(d_params_d_scale, d_params_d_scale) * scale_err**2
        table_cov = jnp.zeros_like(cov)
        chi2_tables = chi2_red
        if model[0] == "transport":  # the tables' own noise (module docstring)
            cell_errors = profiles.slice_cell_errors(noise_c, Medium(jnp.exp(params[0]), jnp.exp(params[1]), eta_c))

            def shifted(delta):
                moved = (args[0][:2] + (profiles.shift_slice(fixed_c, delta),) + args[0][3:],) + args[1:]
                return _residuals(params, moved)

            d_res_d_cells = jax.jacfwd(shifted)(jnp.zeros_like(cell_errors)) * cell_errors   # (m, bins, rho)
            table_residuals = d_res_d_cells.reshape(d_res_d_cells.shape[0], -1)            # whitened, per unit cell noise
            response = -normal_inverse @ (jac.T @ table_residuals)
            table_cov = response @ response.T
            # The residuals' covariance is I + D D^T in whitened units (D: table_residuals): the
            # tables' noise is a shape the model carries and the data's noise does not explain.
            # chi^2 against it is the goodness of fit that the tables allow; against I alone a
            # bright image of marble (1.2e6 walk photons) read 8-17 and "poor" where its
            # estimates were within 1.8 %.
            residuals = _residuals(params, args)
            covariance = jnp.eye(residuals.size, dtype=residuals.dtype) + table_residuals @ table_residuals.T
            # Conjugate gradients (plain XLA), not jnp.linalg.solve's LAPACK call: chosen on 12-06,
            # when CI workers segfaulted in XLA after this fit held the LAPACK solve (the cause,
            # found on 12-07, was the workers' memory maps running out: tests/conftest.py).
            operator = lx.MatrixLinearOperator(covariance, lx.positive_semidefinite_tag)
            whitened = lx.linear_solve(operator, residuals, lx.CG(rtol=1e-12, atol=1e-12, max_steps=4 * residuals.size),
                                       throw=False).value
            chi2_tables = reduced_chi2(residuals @ whitened, m, 2)
        cov = cov + table_cov
        binned, _ = _model(params, args[0])
        positive = usable & (meas > 0)
        rel = jnp.where(positive, binned / jnp.where(positive, meas, 1.0) - 1, 0.0)
        rel_rms = jnp.sqrt(jnp.sum(rel**2) / jnp.maximum(jnp.sum(positive), 1))
        # A parameter that ran off (swapped images: log sigma_a past 709) is reported as a finite
        # 1e304 with an infinite error, not converged, rather than an infinite medium.
        sa, ss = jnp.exp(jnp.clip(params[0], -700.0, 700.0)), jnp.exp(jnp.clip(params[1], -700.0, 700.0))
        sa_err, ss_err = sa * jnp.sqrt(cov[0, 0]), ss * jnp.sqrt(cov[1, 1])
        sa_table, ss_table = sa * jnp.sqrt(table_cov[0, 0]), ss * jnp.sqrt(table_cov[1, 1])
        # The solver stopping is not enough: a parameter that runs off (sigma_s' = 1e29 on a
        # swapped image) "converges" with an error larger than itself, and one that runs to 0
        # (sigma_a when nothing in the data depends on it) leaves J^T J singular, where the
        # pseudo-inverse reports a small error. Converged means a determined estimate: finite,
        # each standard error below its value, and each parameter felt by the data (changing
        # it by a factor e moves the whitened residuals by more than one).
        values = jnp.stack([sa, ss, sa_err, ss_err])
        felt = jnp.sqrt(jnp.sum(jac**2, axis=0)) > 1.0
        determined = jnp.all(jnp.isfinite(values)) & (sa_err < sa) & (ss_err < ss) & jnp.all(felt)
        # The model's whole-plane total at the estimate, on the full grid (reported, not fitted).
        plane_total = observable(*model, Medium(sa, ss, eta_c), k, grid_r, fixed_c)[1]
        return (sa, ss, sa_err, ss_err, plane_total, rel_rms, chi2_red, loss, steps, sa_table, ss_table,
                binned, chi2_tables, ok & determined)

    return jax.vmap(one, in_axes=(1, 1, 0, 0, 0, 0, 0, 0))(measured, stderr, totals, total_errs, scale_errs, eta, fixed,
                                                          noise)


def _starting_points(total, eta, n_starts, *, scan):
    """(log sigma_a, log sigma_s') candidates for one channel: mean free paths log-spaced from
    0.01 to 10 mm at the reduced albedo the total implies under the dipole (``scan=False``),
    or, to be scanned (only evaluated), 0.001 to 100 mm at three albedos: the implied one and
    1 - alpha' halved and doubled (transport's total differs from the dipole's)."""
    alpha, one_minus = dipole.reduced_albedo_from_reflectance(jnp.clip(total, 1e-4, 1 - 1e-6), eta)
    if not scan:
        mfp = jnp.geomspace(0.01, 10.0, n_starts)
        return jnp.log(jnp.maximum(one_minus, 1e-8)) - jnp.log(mfp), jnp.log(jnp.maximum(alpha, 1e-8)) - jnp.log(mfp)
    mfp = jnp.geomspace(1e-3, 1e2, n_starts)
    absorbing = jnp.clip(one_minus * jnp.array([0.5, 1.0, 2.0]), 1e-8, 1 - 1e-8)
    log_sa = (jnp.log(absorbing)[:, None] - jnp.log(mfp)[None, :]).reshape(-1)
    log_ss = (jnp.log1p(-absorbing)[:, None] - jnp.log(mfp)[None, :]).reshape(-1)
    return log_sa, log_ss


def fit_medium(profile, stderr, eta, *, pixel_radii, bin_index, total_reflectance=None, total_stderr=None,
               field_radii=None, pixel_area: float | None = None, scale_stderr=None,
               beam_sigma: float = 0.0, model: str = "dipole", g: float = 0.0, view_cos: float | None = None,
               init: str = "scan", n_starts: int | None = None,
               max_steps: int = 200,
               rtol: float = 1e-8, atol: float = 1e-10, grid: hankel.HankelGrid | None = None) -> MediumFit:
    r"""Fit sigma_a and sigma_s' per channel to binned radial profiles.

    Parameters
    ----------
    profile, stderr : array_like, shape ``(n_bins, C)`` [1/mm^2]
        Mean calibrated reflectance in each radial bin and its standard error. Bins with a
        non-positive mean or error are ignored.
    eta : float or array_like ``(C,)``
        Relative index of refraction (given, not fitted).
    pixel_radii : array_like ``(P,)`` [mm], keyword-only
        Distance of every pixel used from the beam centre.
    bin_index : array_like ``(P,)`` of int, keyword-only
        The bin each pixel belongs to (the model is averaged over the same pixels); the
        value ``n_bins`` marks padding.
    total_reflectance, total_stderr : array_like ``(C,)``, optional, keyword-only
        Measured total diffuse reflectance and its standard error (default 1e-3 of it);
        adds the constraint residual.
    field_radii : array_like ``(Q,)`` [mm], optional, keyword-only
        Radii of every pixel of the field of view over which ``total_reflectance`` was
        summed, and ``pixel_area`` [mm^2] their area: the model's total is then summed over
        the same pixels. Without them the model's total is over the whole plane, which is
        biased when light leaves the image (translucent materials, small fields of view).
    scale_stderr : array_like ``(C,)``, optional, keyword-only
        Relative standard error of a calibration factor shared by every bin and the total
        (the reference's sum); propagated into the parameters' errors.
    beam_sigma : float [mm], keyword-only
        Standard deviation of the Gaussian beam; 0 for a point beam.
    model : {"dipole", "transport"}, keyword-only
        The profile model (see the module docstring). ``"transport"`` needs eta in 1.0-1.6.
    g : float, keyword-only
        Henyey-Greenstein mean cosine of the material, for ``model="transport"`` (one of the
        tabulated 0, 0.5, 0.8, 0.9); the dipole depends on sigma_s' only.
    view_cos : float, optional, keyword-only
        None (default): ``profile`` is the exitance per unit entering flux (a tally of light
        leaving, e.g. a Monte Carlo profile). A cosine in (0, 1]: ``profile`` is a camera's
        view at that angle calibrated by a white Lambertian reference,
        :math:`\pi (1 - F(0)) L(r, \theta)` per unit incident flux (the beam loses
        :math:`F(0)` at entry; a white reference of reflectance :math:`\rho` shows radiance
        :math:`\rho E / \pi`, so ``rho * pixel / (A * sum(reference))`` is this quantity).
        The transport model uses :func:`jsss.transport.radiance`, the dipole the diffusion
        exit law :func:`jsss.fresnel.exit_lobe`.
    init : {"scan", "multistart"}, keyword-only
        ``"scan"`` (default): ``n_starts`` (default 16) mean free paths log-spaced from 0.001
        to 100 mm, at three albedos around the one the total implies, are evaluated (not
        solved), and one Gauss-Newton solve starts from the best; a channel whose
        solve does not converge is solved again as ``"multistart"`` and the lower loss kept.
        ``"multistart"``: a solve from each of ``n_starts`` (default 7) mean free paths from
        0.01 to 10 mm, the best kept (every start runs until the slowest is done: about
        7 times the cost).
    grid : HankelGrid, optional, keyword-only
        The transform grid (default :func:`jsss.layers.hankel.hankel_grid`, built once per process).

    Returns
    -------
    MediumFit
    """
    if model not in MODELS:
        raise ValueError(f"fit_medium(model={model!r}): valid models are {MODELS}.")
    if model == "transport":
        transport.check_supported(eta, g)
    if view_cos is not None and not 0 < float(view_cos) <= 1:
        raise ValueError(f"fit_medium(view_cos=...) must lie in (0, 1] (the cosine of the camera's angle to the "
                         f"normal) or be None for exitance; got {view_cos}.")
    measured = jnp.asarray(profile, dtype=jnp.result_type(float))
    warn_if_low_precision(measured, what="fit_medium", needs="its 1e-4 noise-free recovery (float64 fits)")
    if measured.ndim == 1:
        measured = measured[:, None]
    errors = jnp.broadcast_to(jnp.asarray(stderr, measured.dtype).reshape(measured.shape[0], -1), measured.shape)
    n_bins, n_channels = measured.shape
    eta = jnp.broadcast_to(jnp.asarray(eta, measured.dtype), (n_channels,))
    if total_reflectance is None:
        totals = jnp.full((n_channels,), 0.5, measured.dtype)
        total_errs = jnp.zeros((n_channels,), measured.dtype)  # no constraint
    else:
        totals = jnp.broadcast_to(jnp.asarray(total_reflectance, measured.dtype), (n_channels,))
        total_errs = (1e-3 * totals if total_stderr is None
                      else jnp.broadcast_to(jnp.asarray(total_stderr, measured.dtype), (n_channels,)))
    if (field_radii is None) != (pixel_area is None):
        raise ValueError("fit_medium needs both field_radii and pixel_area, or neither.")
    grid = hankel.hankel_grid() if grid is None else grid
    grid_r = np.asarray(grid.r, dtype=float)
    inverse = np.asarray(grid.inverse_matrix, dtype=float)
    pixel_r = np.asarray(pixel_radii, dtype=float).reshape(-1)
    bin_index = np.asarray(bin_index).reshape(-1)
    real = bin_index < n_bins  # bin_index == n_bins marks padding
    counts = np.maximum(np.bincount(bin_index[real], minlength=n_bins), 1)
    bins_matrix = _interpolation_rows(grid_r, pixel_r[real], bin_index[real], n_bins, 1.0 / counts[bin_index[real]])
    # The beam multiplies the spectrum; for transport the forward transform (profile on the
    # grid -> spectrum) is folded in too, so a model evaluation is one small mat-vec instead
    # of the grid's dense transform (about 1 ms of the 1.3 ms per evaluation before).
    beam = np.exp(-np.asarray(grid.k, float) ** 2 * float(beam_sigma) ** 2 / 2)

    forward = np.asarray(grid.forward_matrix, float) if model == "transport" else None

    def from_values(from_spectrum):  # (..., K) acting on the spectrum -> acting on the model's values
        with_beam = from_spectrum * beam
        return with_beam if forward is None else with_beam @ forward

    bins_operator = jnp.asarray(from_values(np.asarray(scipy.sparse.csr_matrix(bins_matrix) @ inverse)),
                                measured.dtype)
    total_operator = None
    if field_radii is not None:
        field = np.asarray(field_radii, dtype=float).reshape(-1)
        row = _interpolation_rows(grid_r, field, np.zeros(field.size, dtype=int), 1, float(pixel_area))
        total_operator = jnp.asarray(from_values((row @ inverse)[0]), measured.dtype)
    scale_errs = jnp.broadcast_to(jnp.asarray(0.0 if scale_stderr is None else scale_stderr, measured.dtype),
                                  (n_channels,))
    options = dict(max_steps=max_steps, rtol=rtol, atol=atol,
                   model=(model, float(g), None if view_cos is None else float(view_cos)))
    # The tables at this eta and observable, once (the fit holds both fixed).
    cos_exit = None if view_cos is None else float(view_cos)
    fixed = transport.fixed_slice(eta, g=float(g), cos_exit=cos_exit) if model == "transport" else None
    noise = profiles.noise_slice(np.asarray(eta), g=float(g), cos_exit=cos_exit) if model == "transport" else None
    operands = (measured, errors, totals, total_errs, scale_errs, eta, fixed, noise,
                jnp.asarray(grid.k, measured.dtype), jnp.asarray(grid.r, measured.dtype), bins_operator, total_operator)
    if init not in ("scan", "multistart"):
        raise ValueError(f"fit_medium(init={init!r}): valid values are 'scan' and 'multistart'.")
    multistart = init == "multistart"
    out = _fit_channels(*operands, **options, multistart=multistart,
                        n_starts=n_starts or (7 if multistart else 16))
    if not multistart and not bool(np.all(np.asarray(out[-1]) & (np.asarray(out[-2]) <= POOR_FIT_CHI2))):
        # A channel the seeded solve left unconverged, or converged where chi^2/dof says the model
        # does not fit (a valley away from the truth: on three exact-direction walk images at
        # albedo' 0.7 the scan's best start led to sigma_s' 24 times too small, chi^2/dof 6e3-9e3,
        # where every start finds the truth at 1.1-1.3): solve it from every start, keep the lower loss.
        retry = _fit_channels(*operands, **options, multistart=True, n_starts=7)
        better = np.asarray(retry[7]) < np.asarray(out[7])
        out = tuple(jnp.where(better.reshape(better.shape + (1,) * (np.ndim(a) - 1)), b, a) for a, b in zip(out, retry))
    sa, ss, sa_err, ss_err, total, rel, chi2, _, steps, sa_table, ss_table, binned, chi2_tables, ok = out
    return MediumFit(Medium(sa, ss, eta), sa_err, ss_err, total, rel, chi2, steps, ok, sa_table, ss_table, binned.T,
                     chi2_tables)
