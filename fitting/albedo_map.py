r"""Recover a per-texel colour (albedo) map and one mean free path per channel from photos.

The scene's material is a homogeneous medium under texture-space diffusion (d'Eon, Luebke,
Enderton 2007 sec. 5) with a colour map :math:`c(x)` (:mod:`jsss.render.surface_maps`; with
``texturing = "pre-post"``, :math:`M = \sqrt{c}\,R * (\sqrt{c}\,E)`). A photo's pixels
:math:`I_p` are fitted by :math:`g\,L_p(c, \ell)`, the renderer's own texture-space frame, with

* :math:`u = \ln c` per map texel and channel (the map stays positive; one unknown per texel),
* :math:`\ell_k = \ln \mathrm{mfp}_k` per channel, the medium's mean free path
  :math:`1/\sigma_t'` [mm], with its reduced albedo :math:`\alpha' = \sigma_s'/\sigma_t'` held at the
  scene's. For the dipole :math:`R_d` depends on :math:`\alpha'` (and :math:`\eta`) alone, so this
  holds the medium's total reflectance: a change of mean free path only rescales the profile in
  space, :math:`R(r) = \mathrm{mfp}^{-2} f(r/\mathrm{mfp})`. That removes the degeneracy between the
  map's scale and the medium's own :math:`R_d` (the map carries the colour, relative to the held
  medium), and the exposure ``gain`` must be given for the same reason (brightness is
  gain x map x R_d; a reference's relative error ``gain_err`` is added to every texel's error in
  quadrature: it moves the whole map together). So is the renderer's own error in each channel's
  light (``model_error``, :data:`fitting.render.MODEL_ERROR` by default): a channel's subsurface
  light scaled by :math:`1 + \epsilon` is drawn exactly by its map scaled by :math:`1 + \epsilon`
  at the same mean free path (the frame is linear in c), so it moves that channel's whole map
  and nothing else (tested).

The model reuses the renderer's stages (:class:`jsss.render.methods.TextureSpace`): the
irradiance at a white map, the texel geometry, the blur chain and the texel-to-pixel lookup are
computed once per fit; each evaluation takes the colour layer on the way in
(:meth:`~jsss.render.methods.TextureSpace.surface`), the blur
(:meth:`~jsss.render.methods.TextureSpace.diffusion`), the weights of the render profile for the
mean free path on the plan's fixed variances (:func:`jsss.render.profiles.render_profile`, as
:func:`fitting.render.fit_render` does), the colour layer on the way out
(:meth:`~jsss.render.methods.TextureSpace.texel_exitance`) and the camera pass (single scattering
under the map, specular held). What else depends on the medium (the oblique-incidence law, the
exit law, the deposit depth) is held at the start's; the fit re-plans when the fitted mean free path moves the
planner's variances.

Solver: Gauss-Newton on the whitened residuals :math:`r = (g L - I)/s`, each step's normal
equations :math:`J^T J\,\delta = -J^T r` solved by conjugate gradients (:class:`lineax.CG`'s
iteration and stop, without its extra products: :func:`_conjugate_gradients`) on
:math:`v \mapsto J^T (J v)` from :func:`jax.linearize` and its transpose: the Jacobian is never
formed. CG runs on the system scaled by its diagonal, :math:`D^{-1/2} A D^{-1/2}`, whose texel
entries are probed (nine products: the map coloured on a 3 x 3 lattice, random signs per
colour; again once the unknowns moved by :data:`DIAGONAL_DRIFT`) and whose mean free path entries
are exact (one JVP); a halving line search. Each step's CG stops at Eisenstat and Walker's (1996,
choice 2) forcing term, from 0.5 far from the minimum down to ``cg_rtol`` as the gradient falls,
and the fit ends only on a step solved to ``cg_rtol``; a round before the last (its mean free path
only refreshes the frame) ends on a loose step (on the tests' plane: CG 2890 -> 1533 iterations,
the result within its errors). The programs (residuals, images, diagonal, solves) are compiled once per
*structure* -- map size, the plan's layout of the geometry (:mod:`jsss.render.programs`), dtypes
-- and kept across fits, with the geometry's arrays as their arguments: a second fit of the
same scene compiles none of them. The error probes' solves share one program
(:meth:`_Programs._solve_each`): the residuals are linearised once for all of them.

Uncertainty: the covariance is :math:`s^2 (J^T J)^{-1}` with :math:`s^2 = \max(1, \chi^2/\nu)`
(:mod:`fitting.statistics`). Its diagonal is estimated by *probing* (``errors="probe"``): the map
texels are coloured in a ``probe_spacing`` x ``probe_spacing`` lattice; for each colour one CG
solve :math:`x = (J^T J)^{-1} v` with :math:`v` random signs :math:`\epsilon_i` on that colour's
texels (all three channels at once: the channels do not couple), and
:math:`\epsilon_i x_i` estimates :math:`(J^T J)^{-1}_{ii}` without bias; its scatter comes from
the inverse's entries between texels ``probe_spacing`` apart, which the profile's local support
makes small. The mean free paths' variances are exact (one solve). ``errors="exact"`` forms
:math:`J` (by forward mode, one column per unknown) and inverts :math:`J^T J`: for small maps,
and what the tests check the probe against.

Texels the camera does not see (the fitted pixels' bilinear lookup weight on them below
``min_pixels``) are not fitted: they keep the start (the seen texels' median), their error is
infinite, and ``seen`` is false there.
"""

from __future__ import annotations

import dataclasses
import functools
import numbers
from dataclasses import dataclass

import equinox as eqx
import jax
from jax.flatten_util import ravel_pytree
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from fitting.render import HUBER_K, MODEL_ERROR, RenderFitError, _huber, estimate_noise, fit_pixels
from fitting.statistics import error_scale, reduced_chi2
from jsss.medium import Medium
from jsss.render import Material, Method, Pass, Scene, plan_scene, render_params
from jsss.render.methods.base import entry_irradiance
from jsss.render.profiles import full_profile, profile_radii, render_profile
from jsss.render.programs import fill, split
from jsss.render.surface_maps import SurfaceMaps

__all__ = ["AlbedoMapError", "AlbedoMapFit", "fit_albedo_map", "without_legs"]


# Re-plan (and recompile) only when a Gaussian's variance moved by more: the weights are refitted
# for the estimate on the fixed variances, whose geometric spacing (about 2.6x) leaves room
VARIANCE_REPLAN = 0.25
MFP_REFRESH = 0.003  # refresh the frame for the estimate when ln mfp moved by more in a round
# The error solves' relative residual (scaled 2-norm): a probe's estimate errs by about this
# fraction of the inverse's diagonal, far below the probing's own scatter (about 15 %). On the
# tests' plane 1e-2 against 1e-3 moved the error map by 0.03 % (median), 0.3 % at most, and
# saved 245 of 1895 CG iterations
ERROR_RTOL = 1e-2
# The mean free paths' (co)variance solve: one solve per fit, whose error enters every texel's
SCHUR_RTOL = 1e-7
# The loosest Gauss-Newton step (CG's relative residual): the forcing terms start here
FORCING_MAX = 0.5
# Texels apart that share a probe of diag(J^T J): 3 x 3 = 9 products each time it is probed
DIAGONAL_SPACING = 3
# The diagonal is probed again once the unknowns (ln c, ln mfp) moved by this much in all since
# it was (summed over steps, the largest change of any one): it only scales CG, and probing it
# every step had been 225 of the 992 products of the 320 x 240 benchmark's fit
DIAGONAL_DRIFT = 0.2


class AlbedoMapError(RenderFitError):
    """The scenes, photos or options cannot be fitted; the message names the value and the fix."""


@dataclass(frozen=True, eq=False)
class AlbedoMapFit:
    """Result of :func:`fit_albedo_map`.

    Attributes
    ----------
    albedo : ndarray (H_m, W_m, 3)
        The colour map in texel order (rows increase with v, as :class:`SurfaceMaps` stores it);
        values above 1 mean the held medium is darker than the photo (its R_d too low).
    albedo_err : ndarray (H_m, W_m, 3)
        One-sigma standard errors; ``inf`` where not ``seen``.
    seen : ndarray (H_m, W_m) of bool
        The texels fitted (the camera's fitted pixels look them up with weight >= ``min_pixels``).
    mean_free_path, mean_free_path_err : ndarray (3,) [mm]
        :math:`1/\\sigma_t'` per channel and its error.
    medium : Medium
        The fitted medium (reduced albedo held at the scene's).
    chi2_reduced : float
        chi^2 per degree of freedom of the whitened residuals.
    converged : bool; steps : int
        Gauss-Newton met its tolerance; Gauss-Newton steps (all rounds).
    images : tuple of ndarray (H, W, 3)
        Each photo's fitted render, gain applied.
    masks : tuple of ndarray (H, W) of bool
        The pixels fitted in each photo.
    sigma : tuple of ndarray (H, W, 3)
        Each pixel's standard error as fitted.
    errors : str
        How the errors were computed ("probe", "exact" or "none").
    cg_steps : int
        Conjugate-gradient iterations, all solves together.
    warnings, history : tuple of str
    profile_model : str
        The profile model of the fit ("dipole" or "transport": the scene material's).
    model_error : float
        The renderer's relative error included in ``albedo_err`` (``fit_albedo_map``'s).
    """

    albedo: np.ndarray
    albedo_err: np.ndarray
    seen: np.ndarray
    mean_free_path: np.ndarray
    mean_free_path_err: np.ndarray
    medium: Medium
    chi2_reduced: float
    converged: bool
    steps: int
    images: tuple
    masks: tuple
    sigma: tuple
    errors: str
    cg_steps: int
    warnings: tuple = ()
    history: tuple = ()
    profile_model: str = "dipole"
    model_error: float = 0.0

    @property
    def image(self) -> np.ndarray:
        """The first photo's fitted render."""
        return self.images[0]


def _check_gain(gain, gain_err, n_views):
    if gain is None:
        raise AlbedoMapError("gain: the photo's exposure is required (photo value per unit linear radiance; 1 for a "
                             "calibrated camera, or fitting.render.gain_from_reference): brightness is gain x map x R_d "
                             "and the map would absorb any error in it.")
    if isinstance(gain, str) or isinstance(gain, bool | np.bool_):
        raise AlbedoMapError(f"gain must be a positive number (or one per photo); got {gain!r}. Fitting it is not "
                             "possible here: it is one direction with the map's scale.")
    gains = np.broadcast_to(np.asarray(gain, float), (n_views,)) if np.ndim(gain) == 0 else np.asarray(gain, float)
    if gains.shape != (n_views,) or not np.all(np.isfinite(gains) & (gains > 0)):
        raise AlbedoMapError(f"gain must be a positive number or one per photo ({n_views}); got {gain!r}.")
    gain_err = float(gain_err)
    if not (np.isfinite(gain_err) and gain_err >= 0):
        raise AlbedoMapError(f"gain_err must be >= 0 (the gain's relative standard error); got {gain_err!r}.")
    return gains, gain_err


def _check_scene(scene: Scene, mesh):
    material = scene.material
    if material.kind != "medium":
        raise AlbedoMapError(f"{scene.source}: fit_albedo_map needs a homogeneous medium under its colour map; the "
                             f"material is {material.kind} (give sigma_a, sigma_s_prime and eta).")
    if material.maps is not None and material.maps.parametric:
        raise AlbedoMapError(f"{scene.source}: [material.maps] has parameter maps (sigma_a ...); remove them: the "
                             "colour map (albedo) is what is fitted.")
    if material.normalize_profile:
        raise AlbedoMapError(f"{scene.source}: normalize_profile is set; remove it (the fit holds the medium's own "
                             "R_d and lets the map carry the colour).")
    if not scene.lights:
        raise AlbedoMapError(f"{scene.source}: the scene has no lights; an unlit photo constrains no map.")
    if mesh is not None and (scene.mesh.uvs.shape != mesh.uvs.shape or not np.array_equal(scene.mesh.uvs, mesh.uvs)):
        raise AlbedoMapError(f"{scene.source}: every (scene, photo) pair must share one mesh and UV layout (the map "
                             "is one texture); this scene's differs from the first's.")


def _medium(ell, albedo, eta):
    """The medium of log mean free paths ``ell`` (3,) at reduced albedo ``albedo`` (3,)."""
    sigma_t = jnp.exp(-ell)
    return Medium((1 - albedo) * sigma_t, albedo * sigma_t, eta)


class _View(eqx.Module):
    """The fixed parts of one photo's frame (arrays traced; the geometry's arrays are in :class:`_Data`)."""

    params: object  # RenderParams in dtype, maps.albedo to be replaced
    blur_params: object  # RenderParams in blur_dtype (variances, stretch) for the diffusion
    irradiance: jax.Array  # (S, S, 3) at a white map [W/mm^2]
    radii: jax.Array
    target: jax.Array
    inverse_sigma: jax.Array  # 0 off the fitted pixels
    gain: jax.Array


def without_legs(plan):
    """``plan`` with the passes "first leg" and "last leg" off: the albedo-map fit's model holds
    neither (with the legs' reads past a rim its recovery missed, tests/fitting/test_albedo_map.py),
    so a render meant to match the fit's model, as its tests' photos, turns them off too."""
    reason = "the albedo-map fit's model holds no leg"
    return plan.replace(Pass.FIRST_LEG, False, reason).replace(Pass.LAST_LEG, False, reason)


def _plan_for(scene, medium, map_shape, accuracy, specular):
    """A texture-space plan of ``scene`` with ``medium`` and a colour map of ``map_shape``."""
    maps = SurfaceMaps(albedo=np.full(tuple(map_shape) + (3,), 0.5),
                       texturing="pre-post" if scene.material.maps is None else scene.material.maps.texturing)
    material = dataclasses.replace(scene.material, medium=medium, maps=maps,
                                   profile_model=scene.material.profile_model, profile=None)
    fit_scene = dataclasses.replace(scene, material=material)
    plan = without_legs(plan_scene(fit_scene, accuracy=accuracy, method=Method.TEXTURE_SPACE))
    if not specular:
        plan = plan.replace(Pass.SPECULAR, False, "the photo holds subsurface light only")
    return fit_scene, plan


def _auto_map_size(prepared, use, texture_size) -> int:
    """The finest power-of-two map whose texel is no smaller than a fitted pixel's footprint
    (median UV step between neighbouring pixels): finer, texels outnumber the pixels that see them."""
    uv = np.asarray(prepared.pixel_uv, float)
    both = use[:, 1:] & use[:, :-1]
    step = np.linalg.norm(uv[:, 1:] - uv[:, :-1], axis=-1)[both]
    both_v = use[1:, :] & use[:-1, :]
    step = np.concatenate([step, np.linalg.norm(uv[1:, :] - uv[:-1, :], axis=-1)[both_v]])
    if step.size == 0:
        return texture_size
    texels = float(np.median(step)) * texture_size
    shrink = 2 ** int(np.ceil(np.log2(max(texels, 1.0))))
    return max(2, texture_size // shrink)


def fit_albedo_map(scene, photo=None, *, gain=None, gain_err: float = 0.0, model_error: float = MODEL_ERROR,
                   sigma=None, noise="estimate", mask=None,
                   saturation: float | None = None, map_size: int | None = None, init_mean_free_path=None,
                   accuracy: float = 0.001, specular: bool = True, min_pixels: float = 0.5, max_steps: int = 12,
                   cg_rtol: float = 1e-3, cg_max_steps: int = 500, errors: str = "probe", probe_spacing: int = 4,
                   seed: int = 0, replans: int = 2, unconstrained: float = 0.5, loss: str = "huber", dtype=jnp.float64,
                   blur_dtype=None, progress=None) -> AlbedoMapFit:
    r"""Fit a per-texel colour map and one mean free path per channel to photos (module docstring).

    Parameters
    ----------
    scene : Scene, or a list of (Scene, photo) pairs
        Geometry, camera, lights and the homogeneous medium (its reduced albedo and eta are
        held; its mean free path starts the fit). Several pairs -- other lights or views of one
        mesh -- are fitted jointly: one map, one medium.
    photo : array (H, W, 3)
        Linear radiance up to ``gain``, at the camera's resolution (omit with a list of pairs).
    gain : float or sequence of floats (one per photo)
        Required: photo value per unit linear radiance. ``gain_err``: its relative error.
    model_error : float
        The renderer's relative error in each channel's subsurface light, in [0, 1) (default
        :data:`fitting.render.MODEL_ERROR`, its frames against a path tracer; 0 for a photo jsss
        rendered itself): added in quadrature to every seen texel's relative error, as
        ``gain_err`` is, since it moves the channel's whole map (module docstring).
    sigma : array broadcastable to the photo (or one per photo), optional
        Each pixel's standard error. Else ``noise``: a relative error (times the pixel value,
        floored at 1 % of the 99th percentile), or ``"estimate"`` (:func:`fitting.render.estimate_noise`
        from a first fit's residuals, then fitted again).
    mask, saturation
        Pixels used (:func:`fitting.render.fit_pixels`); one mask for all photos.
    map_size : int, optional
        Texels per side of the fitted map (default: the finest power of two whose texel is no
        smaller than the median fitted pixel's footprint, at most the plan's texture size).
    init_mean_free_path : (3,) [mm], optional
        Start of the mean free path (default: the scene's medium's).
    accuracy : float
        The planner's accuracy for the render profile (as :func:`fitting.render.fit_render`).
    specular : bool
        Render the (held) surface reflection; False for a photo of subsurface light only.
    min_pixels : float
        A texel is fitted when the fitted pixels' bilinear lookup weights on it sum to at least this.
    max_steps, cg_rtol, cg_max_steps
        Gauss-Newton steps per round (a step solved again at ``cg_rtol`` after a loose one found no
        decrease counts; the last allowed step is solved at ``cg_rtol``); CG's relative tolerance
        for the last steps (the floor of the forcing terms, module docstring) and its iterations
        per solve.
    errors : {"probe", "exact", "none"}
        How the error map is computed (module docstring); ``probe_spacing`` and ``seed`` set the probing.
    unconstrained : float
        Relative error of a texel above which it is reported (warning) as poorly constrained.
    loss : {"huber", "squared"}
        ``"huber"`` (default): Huber's loss on the whitened residuals (quadratic within
        :data:`fitting.render.HUBER_K` = 1.345 standard errors, linear beyond), so that fireflies and
        hot pixels do not steer their texels; chi^2/dof then comes from the median square. As
        :func:`fitting.render.fit_render`.
    dtype, blur_dtype
        The fit's dtype; the blur's (default ``dtype``; float32 halves the costliest pass).

    Returns
    -------
    AlbedoMapFit

    Raises
    ------
    AlbedoMapError (a ValueError)
        A material that is not a homogeneous medium, no gain, photos that do not match the
        cameras, scenes that do not share a mesh, or an option out of range.
    """
    say = progress if progress is not None else (lambda message: None)
    pairs = list(scene) if photo is None and isinstance(scene, list | tuple) else [(scene, photo)]
    if not pairs or any(p is None for _, p in pairs):
        raise AlbedoMapError("photo: give a photo, or a list of (scene, photo) pairs as the first argument.")
    gains, gain_err = _check_gain(gain, gain_err, len(pairs))
    if not (np.isfinite(float(model_error)) and 0 <= float(model_error) < 1):
        raise AlbedoMapError(f"model_error must be a relative error in [0, 1) (0.015 for 1.5 %); got {model_error!r}.")
    if loss not in ("huber", "squared"):
        raise AlbedoMapError(f"loss must be 'huber' or 'squared'; got {loss!r}.")
    robust = loss == "huber"
    if errors not in ("probe", "exact", "none"):
        raise AlbedoMapError(f"errors must be 'probe', 'exact' or 'none'; got {errors!r}.")
    for name, value, low in (("probe_spacing", probe_spacing, 1), ("max_steps", max_steps, 1),
                             ("cg_max_steps", cg_max_steps, 1)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
            raise AlbedoMapError(f"{name} must be an integer >= {low}; got {value!r}.")
    if not (min_pixels > 0 and np.isfinite(min_pixels)):
        raise AlbedoMapError(f"min_pixels must be > 0 (pixels' worth of lookup weight per texel); got {min_pixels!r}.")
    estimate = isinstance(noise, str)
    if estimate and noise != "estimate":
        raise AlbedoMapError(f"noise must be 'estimate' or a positive relative error; got {noise!r}.")
    if not estimate and not (np.isfinite(float(noise)) and float(noise) > 0):
        raise AlbedoMapError(f"noise must be 'estimate' or a positive relative error; got {noise!r}.")
    estimate = estimate and sigma is None
    first = pairs[0][0]
    for s, _ in pairs:
        _check_scene(s, first.mesh)
    material = first.material
    profile_model, g = material.profile_model, material.g
    medium0 = material.medium
    eta = jnp.broadcast_to(jnp.asarray(medium0.eta, dtype), (3,))
    albedo_prime = jnp.asarray(np.broadcast_to(np.asarray(medium0.sigma_s_prime, float) /
                                               (np.asarray(medium0.sigma_a, float) +
                                                np.asarray(medium0.sigma_s_prime, float)), (3,)), dtype)
    mfp0 = (1.0 / (np.asarray(medium0.sigma_a, float) + np.asarray(medium0.sigma_s_prime, float))
            if init_mean_free_path is None else np.asarray(init_mean_free_path, float))
    mfp0 = np.broadcast_to(mfp0, (3,))
    if not np.all(np.isfinite(mfp0) & (mfp0 > 0)):
        raise AlbedoMapError(f"init_mean_free_path must be 3 positive lengths [mm]; got {init_mean_free_path!r}.")
    photos, uses = [], []
    for s, p in pairs:
        p = np.asarray(p, float)
        use = fit_pixels(s, p, mask=mask, saturation=saturation)
        if use.sum() < 10:
            raise AlbedoMapError(f"photo of {s.source}: only {int(use.sum())} pixels of the object can be fitted; "
                                 "is the camera looking at it?")
        photos.append(p)
        uses.append(use)
    sigmas = _sigmas(sigma, noise, estimate, photos, uses)
    ell = jnp.log(jnp.asarray(mfp0, dtype))
    # The map's size, from the first view's plan at the start
    _, plan0 = _plan_for(first, _medium(ell, albedo_prime, eta), (2, 2), accuracy, specular)
    S = plan0.method_config.size
    if map_size is None:
        fit_scene, _ = _plan_for(first, _medium(ell, albedo_prime, eta), (S, S), accuracy, specular)
        map_size = _auto_map_size(plan0.method_config.prepare(fit_scene, plan0), uses[0], S)
    if isinstance(map_size, bool) or not isinstance(map_size, numbers.Integral) or not 2 <= map_size <= S:
        raise AlbedoMapError(f"map_size must be an integer from 2 to the plan's texture size {S}; got {map_size!r}.")
    shape = (int(map_size), int(map_size))
    notes, history = [], []
    steps = cg_total = 0
    say("planning and the fixed passes")
    model = _Model(pairs, photos, uses, sigmas, gains, shape, ell, albedo_prime, eta, accuracy, specular,
                   profile_model, g, dtype, blur_dtype, cg_rtol, cg_max_steps, robust)
    u = model.start_map(ell, min_pixels)
    for round_ in range(replans + 1):
        # A round before the last ends on a loose step (its mean free path only refreshes the
        # frame); the last, or one whose mean free path stayed, is finished at cg_rtol
        final = round_ == replans
        say(f"round {round_ + 1}: Gauss-Newton on {int(model.free.sum())} texels x 3 channels")
        u, ell, n, cg, converged = model.solve(u, ell, max_steps, finish=final and not estimate)
        steps, cg_total = steps + n, cg_total + cg
        if estimate:
            expected = model.images(u, ell)
            sigmas = tuple(estimate_noise(p - e, e, m) for p, e, m in zip(photos, expected, uses))
            model = model.with_sigma(sigmas)
            say("noise estimated from the first fit's residuals: solving again with it")
            u, ell, n, cg, converged = model.solve(u, ell, max_steps, finish=final)
            steps, cg_total, estimate = steps + n, cg_total + cg, False
            history.append("noise estimated from the photo (adjacent residuals)")
        moved = float(np.max(np.abs(np.asarray(ell) - model.ell)))
        if final or moved <= MFP_REFRESH:
            if not final:
                u, ell, n, cg, converged = model.solve(u, ell, max_steps, finish=True, tight=True)
                steps, cg_total = steps + n, cg_total + cg
            break
        # The frame's medium-dependent parts (profile radii, incidence law) were the round's start's:
        # refreshed for the estimate, and re-planned (recompiled) only where the Gaussians moved
        _, next_plan = _plan_for(first, _medium(ell, albedo_prime, eta), shape, accuracy, specular)
        before, after = np.asarray(model.plans[0].variances), np.asarray(next_plan.variances)
        if len(before) == len(after) and np.max(np.abs(np.log(after / before))) <= VARIANCE_REPLAN:
            model.refresh(ell)
            history.append(f"round {round_ + 2}: the frame refreshed for the fitted mean free path (moved "
                           f"{100 * moved:.1f} %)")
        else:
            model = _Model(pairs, photos, uses, model.sigmas, gains, shape, ell, albedo_prime, eta, accuracy,
                           specular, profile_model, g, dtype, blur_dtype, cg_rtol, cg_max_steps, robust)
            model.set_seen(min_pixels)
            history.append(f"round {round_ + 2}: re-planned for the fitted mean free path (the Gaussians moved)")
    r = model.residuals(u, ell)
    m = int(sum(int(x.sum()) for x in uses)) * 3
    n_params = int(model.free.sum()) * 3 + 3
    chi2 = reduced_chi2(float(r @ r), m, n_params)
    if robust:  # chi^2 from the median square (0.4549 for a unit Gaussian), as fit_render
        plain = np.concatenate([((i - p) / s)[use].reshape(-1) for i, p, s, use in
                                zip(model.images(u, ell), photos, model.sigmas, uses)])
        chi2 = float(np.median(plain**2) / 0.45494) * m / max(m - n_params, 1)
        outliers = float(np.mean(np.abs(plain) > 5))
        if outliers > 0.001:
            notes.append(f"{100 * outliers:.2g} % of the fitted pixels lie beyond 5 standard errors (fireflies, hot "
                         f"pixels, or a part of the scene the model lacks); Huber's loss (k = {HUBER_K}) kept them "
                         "from steering their texels")
    scale = error_scale(chi2)
    var_u, var_ell, cg = model.variances(u, ell, errors, probe_spacing, seed)
    cg_total += cg
    albedo = np.asarray(jnp.exp(u))
    seen = np.asarray(model.seen)
    # A probe estimate that came out non-positive (its scatter exceeded the variance) is no error: inf, flagged
    rel = np.sqrt(np.where(var_u > 0, var_u * scale, np.inf) + gain_err**2 + float(model_error)**2)
    if model_error > 0:
        history.append(f"the map's errors include the renderer's own, {100 * float(model_error):g} % of each channel's "
                       "subsurface light (model_error), shared by all texels of a channel")
    albedo_err = np.where(seen[..., None], albedo * rel, np.inf)
    mfp = np.exp(np.asarray(ell))
    mfp_err = mfp * np.sqrt(np.clip(var_ell * scale, 0, None))
    if errors == "probe" and np.any(seen[..., None] & ~(var_u > 0)):
        notes.append(f"{int(np.sum(seen[..., None] & ~(var_u > 0)))} texel errors came out non-positive from the "
                     "probing (its scatter); they are reported as infinite: use probe_spacing larger, or "
                     "errors='exact'")
    loose = seen[..., None] & ~(rel <= unconstrained)
    if loose.any():
        notes.append(f"{int(loose.any(-1).sum())} seen texels have a relative error above {100 * unconstrained:g} % "
                     "(poorly constrained: grazing or barely in view)")
    if chi2 > 4:
        notes.append(f"poor fit: chi2/dof {chi2:.1f}; the errors are widened by its square root")
    if np.any(seen[..., None] & (albedo > 1)):
        notes.append("map values above 1: the held medium's R_d is below what the photo shows")
    medium = _medium(ell, albedo_prime, eta)
    medium = Medium(np.asarray(medium.sigma_a), np.asarray(medium.sigma_s_prime), np.asarray(medium0.eta))
    images = tuple(np.asarray(i) for i in model.images(u, ell))
    return AlbedoMapFit(albedo, albedo_err, seen, mfp, mfp_err, medium, chi2,
                        bool(converged) and bool(np.all(np.isfinite(mfp_err))), steps, images, tuple(uses),
                        tuple(np.asarray(s) for s in sigmas), errors, cg_total, tuple(notes), tuple(history),
                        profile_model, float(model_error))


def _sigmas(sigma, noise, estimate, photos, uses):
    out = []
    for k, (p, use) in enumerate(zip(photos, uses)):
        if sigma is not None:
            s = sigma[k] if isinstance(sigma, list | tuple) else sigma
            try:
                s = np.broadcast_to(np.asarray(s, float), p.shape)
            except ValueError:
                raise AlbedoMapError(f"sigma: shape {np.shape(s)} does not broadcast to the photo's {p.shape}.") from None
            if not (np.isfinite(s[use]).all() and (s[use] > 0).all()):
                raise AlbedoMapError("sigma: every fitted pixel's standard error must be finite and > 0.")
        else:
            relative = 0.05 if estimate else float(noise)
            floor = 0.01 * np.percentile(np.abs(p[use]), 99, axis=0)
            s = relative * np.maximum(np.abs(p), np.maximum(floor, 1e-300))
        out.append(s)
    return tuple(out)


def _hashable(value):
    return tuple(np.asarray(value, float).reshape(-1).tolist()) if np.ndim(value) else float(value)


@dataclass(frozen=True)
class _Structure:
    """What a fit's programs are compiled for: equal structures share programs (:func:`_programs`)."""

    layouts: tuple  # (method configuration, jsss.render.programs.Layout) per photo
    shape: tuple  # the map's (H_m, W_m)
    robust: bool
    dtype: str
    blur_dtype: str
    profile_model: str
    g: float | tuple
    cg_max_steps: int


class _Data(eqx.Module):
    """The arrays the programs read besides the unknowns and the views."""

    arrays: tuple  # per photo, the prepared geometry's arrays (jsss.render.programs.split)
    free: jax.Array  # (H_m, W_m, 1): 1 on the fitted texels
    albedo_prime: jax.Array
    eta: jax.Array
    diagonal_signs: jax.Array  # (DIAGONAL_SPACING^2, H_m, W_m, 3): the probes of diag(J^T J)


def _conjugate_gradients(mv, b, atol, max_steps):
    """Conjugate gradients on ``mv`` (symmetric positive definite) from zero: ``(y, steps, ok)``.

    ``lineax.CG(rtol=0, atol=atol, stabilise_every=None)``'s iteration and stopping rule (while
    the residual's 2-norm or the last update's exceeds ``atol``, its curvature positive, at most
    ``max_steps``; tested to agree), without its product ``A y0`` at the start (y0 = 0: the
    residual is ``b``). Against lineax's default it also leaves out the residual recomputed as
    ``b - A y`` every tenth iteration, which corrects the recursive residual's rounding drift:
    in float64 on the 320 x 240 benchmark the iterations stayed 627 and the answer the same to
    1e-10 (64 x 48: 1533 -> 1531, 128 x 96: 1271 -> 1283 iterations); the two products had been
    85 of its 712. In float32 the drift is larger (a random system: 285 -> 303 iterations)."""
    dot = lambda a, c: sum(jnp.sum(p * q) for p, q in zip(jax.tree.leaves(a), jax.tree.leaves(c)))
    leaves = jax.tree.leaves(b)
    rcond = 2 * jnp.finfo(jnp.result_type(*leaves)).eps * sum(leaf.size for leaf in leaves)  # lineax's

    def not_converged(r, diff):
        return (optx.two_norm(jax.tree.map(lambda a: a / atol, r)) > 1) | \
            (optx.two_norm(jax.tree.map(lambda a: a / atol, diff)) > 1)

    def cond(state):
        diff, _, r, _, gamma, step = state
        return (gamma > 0) & (step < max_steps) & not_converged(r, diff)

    def body(state):
        _, y, r, p, gamma, step = state
        Ap = mv(p)
        curvature = dot(Ap, p)
        alpha = jnp.where(jnp.abs(curvature) > 100 * rcond * jnp.abs(gamma), gamma / curvature, jnp.nan)
        diff = jax.tree.map(lambda a: alpha * a, p)
        y = jax.tree.map(jnp.add, y, diff)
        r = jax.tree.map(lambda a, c: a - alpha * c, r, Ap)
        gamma_next = dot(r, r)
        p = jax.tree.map(lambda a, c: a + (gamma_next / gamma) * c, r, p)
        return diff, y, r, p, gamma_next, step + 1

    zeros = jax.tree.map(jnp.zeros_like, b)
    start = (jax.tree.map(lambda a: jnp.full_like(a, jnp.inf), b), zeros, b, b, dot(b, b), jnp.asarray(0))
    _, y, _, _, _, steps = jax.lax.while_loop(cond, body, start)
    return y, steps, steps < max_steps


@functools.lru_cache(maxsize=8)
def _programs(structure: _Structure) -> _Programs:
    """The compiled residuals, images, diagonal and solves of ``structure``: a second fit of the same
    scene layout (another photo, light direction or start) compiles none of them (they had been
    recompiled per fit: 23.5 s of a 114 s fit of the tests' plane, 2026-12-07)."""
    return _Programs(structure)


class _Programs:
    """The fit's traced functions: the residuals, the images, J^T J's diagonal and the CG solves.

    Everything that changes between fits of one structure (the geometry's arrays, the fitted
    texels, the medium's reduced albedo and eta, the views) is an argument."""

    def __init__(self, structure: _Structure):
        self.structure = structure
        self.dtype = jnp.dtype(structure.dtype)
        self.residuals = eqx.filter_jit(self.raw_residuals)
        self.images = eqx.filter_jit(self._images)
        self.diagonal = eqx.filter_jit(self._diagonal)
        self.solve = eqx.filter_jit(self._solve)
        self.solve_each = eqx.filter_jit(self._solve_each)

    def _prepared(self, data):
        return tuple((method, fill(layout, arrays)) for (method, layout), arrays in zip(self.structure.layouts, data.arrays))

    def _radiance(self, u, ell, data, view, static):
        method, prepared = static
        medium = _medium(ell, data.albedo_prime, data.eta)
        material = Material("fit", np.ones(3), medium=medium, profile_model=self.structure.profile_model,
                            g=np.asarray(self.structure.g) if isinstance(self.structure.g, tuple) else self.structure.g)
        weights = render_profile(material, view.params.variances, radii=view.radii,
                                 medium=medium).weights.astype(self.dtype)
        params = eqx.tree_at(lambda p: (p.weights, p.maps.albedo), view.params, (weights, jnp.exp(u)))
        entry, _, _ = method.surface(params, prepared, self.dtype)
        low = view.blur_params
        blurred = method.diffusion(low, prepared, (view.irradiance * entry).astype(low.variances.dtype))
        M = method.texel_exitance(params, prepared, blurred.astype(self.dtype))
        return view.gain * method.camera(params, prepared, M)

    def raw_residuals(self, x, data, views):
        parts = [((self._radiance(x["u"], x["ell"], data, v, s) - v.target) * v.inverse_sigma).reshape(-1)
                 for v, s in zip(views, self._prepared(data))]
        r = jnp.concatenate(parts)
        return _huber(r) if self.structure.robust else r

    def _images(self, x, data, views):
        return tuple(self._radiance(x["u"], x["ell"], data, v, s) for v, s in zip(views, self._prepared(data)))

    def _cg(self, A, d, b, rtol, forcing):
        # Symmetric Jacobi scaling, D^-1/2 A D^-1/2 y = D^-1/2 b, x = D^-1/2 y: the scaled
        # matrix has a unit diagonal, so y and its residual share units and one 2-norm stop
        # (||r|| <= rtol ||b||) means the same for every texel. lineax's default stop is per
        # element (atol + rtol |b_i|, max norm): the barely seen texels' near-null directions
        # kept it iterating hundreds of times on residuals that move no seen texel.
        root = jax.tree.map(jnp.sqrt, d)
        scaled = lx.FunctionLinearOperator(
            lambda y: jax.tree.map(jnp.divide, A.mv(jax.tree.map(jnp.divide, y, root)), root),
            A.in_structure(), tags=lx.positive_semidefinite_tag)
        rhs = jax.tree.map(jnp.divide, b, root)
        size = jnp.sqrt(sum(jnp.sum(leaf**2) for leaf in jax.tree.leaves(rhs)))
        # Eisenstat and Walker's (1996) choice 2 where ``forcing`` = (the previous step's scaled
        # gradient norm, its tolerance) is given: a loose solve far from the minimum, tightening
        # as the gradient falls; ``rtol`` is then the floor
        previous, eta_previous = forcing
        eta = 0.9 * (size / jnp.where(previous > 0, previous, 1.0)) ** 2
        safeguard = 0.9 * eta_previous**2
        eta = jnp.where(safeguard > 0.1, jnp.maximum(eta, safeguard), eta)
        eta = jnp.where(previous > 0, jnp.clip(eta, rtol, FORCING_MAX), FORCING_MAX)
        rtol = jnp.where(eta_previous >= 0, eta, rtol)
        value, steps, ok = _conjugate_gradients(scaled.mv, rhs, rtol * size, self.structure.cg_max_steps)
        return jax.tree.map(jnp.divide, value, root), steps, ok, size, rtol

    def _solve(self, x, data, views, b, newton, free, rtol, diagonal, forcing):
        """(J^T J)^-1 on the fitted texels of ``b``, or, where ``newton``, of -J^T r (the Gauss-Newton
        step); the mean free paths held where ``free`` is 0. One program for all. ``diagonal``:
        :meth:`_diagonal` at ``x``."""
        A, r, _, vjp, project = self._operator(x, data, views, free)
        d = {"u": diagonal["u"], "ell": jnp.where(free > 0, diagonal["ell"], 1.0)}
        step = jax.tree.map(jnp.negative, project(vjp(r)[0]))
        return self._cg(A, d, jax.tree.map(lambda s, v: jnp.where(newton, s, v), step, b), rtol, forcing)

    def _solve_each(self, x, data, views, bs, rtol, diagonal):
        """(J^T J)^-1 of each of ``bs`` (a leading axis) with the mean free paths held, at the fixed
        tolerance ``rtol``: the error probes, one after another in one program. The residuals are
        linearised once for all of them (a program per probe had repeated that and the unused
        J^T r each time: 16 probes 17 -> 13 s). Batched instead (vmap), one CG iteration's
        products had cost more than the probes' one at a time (23 s)."""
        free = jnp.zeros((), self.dtype)
        A, _, _, _, _ = self._operator(x, data, views, free)
        d = {"u": diagonal["u"], "ell": jnp.ones_like(diagonal["ell"])}
        fixed = (jnp.zeros((), self.dtype), -jnp.ones((), self.dtype))
        values, steps, ok, _, _ = jax.lax.map(lambda b: self._cg(A, d, b, rtol, fixed), bs)
        return values, jnp.sum(steps), jnp.all(ok)

    def _operator(self, x, data, views, free):
        """J^T J restricted to the fitted texels (identity on the others; on the mean free paths too
        where ``free`` is 0), the residuals, J and J^T (linear maps) and the restriction."""
        seen = data.free
        r, jvp = jax.linearize(lambda y: self.raw_residuals(y, data, views), x)
        vjp = jax.linear_transpose(jvp, x)

        def project(v):
            return {"u": v["u"] * seen, "ell": v["ell"] * free}

        def normal(v):
            w = vjp(jvp(project(v)))[0]
            return {"u": w["u"] * seen + v["u"] * (1 - seen), "ell": w["ell"] * free + v["ell"] * (1 - free)}

        structure = jax.eval_shape(lambda: x)
        A = lx.FunctionLinearOperator(normal, structure, tags=lx.positive_semidefinite_tag)
        return A, r, jvp, vjp, project

    def _diagonal(self, x, data, views):
        """diag(J^T J): the texels' by probing J^T J itself (the map coloured on a lattice
        DIAGONAL_SPACING apart, one product per colour with random signs on its texels: v_t (A v)_t
        is A_tt plus the couplings to same-coloured texels, which the lattice keeps small), the mean
        free paths' exactly (their columns, one JVP: the channels do not couple).

        The scaling CG runs on. An estimate from the pixels each texel covers, weighted by
        (L / s)^2, had been 2.6-16x the true diagonal, unevenly: CG took 322 iterations per
        Gauss-Newton step on the tests' map, 39 with the true diagonal."""
        A, _, jvp, _, _ = self._operator(x, data, views, jnp.asarray(1.0, self.dtype))
        zeros_ell = jnp.zeros_like(x["ell"])
        d_u = jnp.sum(jax.lax.map(lambda sign: sign * A.mv({"u": sign, "ell": zeros_ell})["u"], data.diagonal_signs), 0)
        seen = data.free
        typical = jnp.sum(jnp.where(seen > 0, jnp.abs(d_u), 0.0)) / jnp.maximum(jnp.sum(seen) * 3, 1.0)
        # A texel whose estimate came out tiny or negative (same-coloured couplings larger than its
        # own curvature: barely seen) is scaled as a thousandth of the typical texel
        d_u = jnp.where(seen > 0, jnp.maximum(d_u, 1e-3 * typical), 1.0)
        column = jvp({"u": jnp.zeros_like(x["u"]), "ell": jnp.ones_like(x["ell"])})
        d_ell = jnp.stack([jnp.sum(jnp.concatenate([c.reshape(-1, 3) for c in self._split(column, views)])[:, k] ** 2)
                           for k in range(3)])
        return {"u": d_u, "ell": jnp.maximum(d_ell, 1e-300)}

    def _split(self, flat, views):
        out, at = [], 0
        for v in views:
            n = v.target.size
            out.append(flat[at:at + n])
            at += n
        return out


class _Model:
    """The fit's frames for every photo, its residuals and its linear solves (programs kept across
    fits of one structure, :func:`_programs`)."""

    def __init__(self, pairs, photos, uses, sigmas, gains, shape, ell, albedo_prime, eta, accuracy, specular,
                 profile_model, g, dtype, blur_dtype, cg_rtol, cg_max_steps, robust):
        self.dtype, self.shape, self.uses = dtype, shape, uses
        self.cg_rtol = cg_rtol
        # The floor as the programs see it (cg_rtol in the fit's dtype: 1e-3 is 1.00000005e-3 in float32)
        self.cg_floor = float(jnp.asarray(cg_rtol, dtype)) * (1 + 1e-6)
        self.albedo_prime, self.eta = albedo_prime, eta
        self.blur_dtype = dtype if blur_dtype is None else blur_dtype
        self.photos, self.gains, self.sigmas = photos, gains, sigmas
        medium = _medium(ell, albedo_prime, eta)
        statics, plans, scenes = [], [], []
        for s, _ in pairs:
            fit_scene, plan = _plan_for(s, medium, shape, accuracy, specular)
            method = plan.method_config
            statics.append((method, method.prepare(fit_scene, plan)))
            plans.append(plan)
            scenes.append(fit_scene)
        self.statics, self.plans, self.scenes = tuple(statics), tuple(plans), tuple(scenes)
        self.refresh(ell)
        # Texels the fitted pixels look up, in pixels' worth of bilinear weight (the pixels' own map sampler)
        cover = 0.0
        for (method, prepared), use in zip(self.statics, uses):
            read = prepared.shading.colour_map
            _, pull = jax.vjp(read, jnp.zeros(shape + (3,), dtype))
            cover = cover + np.asarray(pull(jnp.asarray(np.repeat(use[..., None], 3, -1), dtype))[0])[..., 0]
        self.cover = cover
        self.seen = self.free = None
        # The sign patterns that probe diag(J^T J) (_diagonal): one per colour of a lattice
        rows, cols = np.indices(shape)
        signs = np.random.default_rng(0).choice([-1.0, 1.0], size=shape + (3,))
        k = DIAGONAL_SPACING
        self.diagonal_signs = jnp.asarray(np.stack([np.where(((rows % k == i) & (cols % k == j))[..., None], signs, 0.0)
                                                    for i in range(k) for j in range(k)]), dtype)
        # The programs are kept across fits (and across this fit's models) for the same structure:
        # the geometry's arrays are their arguments (jsss.render.programs.split), not constants
        layouts, arrays = [], []
        for method, prepared in self.statics:
            layout, held = split(prepared)
            layouts.append((method, layout))
            arrays.append(held)
        self.arrays = jax.tree.map(jnp.asarray, tuple(arrays))  # on the device once, not per call
        self.programs = _programs(_Structure(tuple(layouts), tuple(shape), bool(robust), jnp.dtype(dtype).name,
                                             jnp.dtype(self.blur_dtype).name, profile_model, _hashable(g),
                                             int(cg_max_steps)))

    def refresh(self, ell):
        """The views' data for the medium of ``ell``, on the same plans (traced: nothing recompiles).

        The profile's weights are fitted on the renderer's own radii for that medium (those of
        :func:`jsss.render.render_params`), so that at the fitted medium the model is the
        renderer's frame; the irradiance's oblique-incidence law and single scattering are that
        medium's too."""
        medium = _medium(ell, self.albedo_prime, self.eta)
        medium = Medium(np.asarray(medium.sigma_a), np.asarray(medium.sigma_s_prime), np.asarray(medium.eta))
        views = []
        for fit_scene, plan, (method, prepared), p, use, sig, gain in zip(
                self.scenes, self.plans, self.statics, self.photos, self.uses, self.sigmas, self.gains):
            material = dataclasses.replace(fit_scene.material, medium=medium, profile=None)
            fit_scene = dataclasses.replace(fit_scene, material=material)
            params = render_params(fit_scene, plan, dtype=self.dtype)
            low = render_params(fit_scene, plan, dtype=self.blur_dtype)
            E = entry_irradiance(params, prepared.texel_lights)  # a white map: the entry factor comes per evaluation
            radii = profile_radii(full_profile(material))
            inverse = np.where(use[..., None], 1.0 / np.asarray(sig), 0.0)
            views.append(_View(params, low, E, jnp.asarray(radii, self.dtype),
                               jnp.asarray(np.where(use[..., None], p, 0.0), self.dtype),
                               jnp.asarray(inverse, self.dtype), jnp.asarray(gain, self.dtype)))
        self.views, self.ell = tuple(views), np.asarray(ell)

    def with_sigma(self, sigmas):
        self.sigmas = sigmas
        self.views = tuple(eqx.tree_at(lambda v: v.inverse_sigma, v,
                                        jnp.asarray(np.where(use[..., None], 1.0 / np.asarray(s), 0.0), self.dtype))
                           for v, s, use in zip(self.views, sigmas, self.uses))
        return self

    @property
    def data(self) -> _Data:
        """What the programs read besides the views: the geometry's arrays and the fitted texels."""
        free = np.zeros(self.shape, bool) if self.free is None else self.free  # before set_seen: none yet
        return _Data(self.arrays, jnp.asarray(free[..., None], self.dtype), self.albedo_prime, self.eta,
                     self.diagonal_signs)

    def _residuals(self, x, views):
        return self.programs.residuals(x, self.data, views)

    def _images(self, x, views):
        return self.programs.images(x, self.data, views)

    def _raw(self, x, views):
        return self.programs.raw_residuals(x, self.data, views)

    def _diagonal_of(self, x, views):
        return self.programs.diagonal(x, self.data, views)

    def _solve(self, x, views, b, newton, free, diagonal, rtol=None, forcing=None):
        # newton, free and the tolerance as arrays: as Python scalars they would be static, one
        # program each. A Gauss-Newton step stops at its forcing term (``forcing``: the previous
        # step's scaled gradient norm and tolerance), at least cg_rtol; the error solves at
        # ERROR_RTOL, the mean free paths' at SCHUR_RTOL.
        rtol = rtol if rtol is not None else self.cg_rtol if newton else ERROR_RTOL
        forcing = (0.0, -1.0) if forcing is None else forcing  # (-1: a fixed tolerance)
        return self.programs.solve(x, self.data, views, b, jnp.asarray(newton), jnp.asarray(free, self.dtype),
                                   jnp.asarray(rtol, self.dtype), diagonal,
                                   tuple(jnp.asarray(f, self.dtype) for f in forcing))

    # -- the start and the solves --------------------------------------------------------------
    def start_map(self, ell, min_pixels):
        """ln c per texel: photo over the white map's render, pooled over the pixels that see each texel."""
        ones = jnp.zeros(self.shape + (3,), self.dtype)
        white = self._images({"u": ones, "ell": ell}, self.views)
        num = den = 0.0
        for (method, prepared), v, w, use in zip(self.statics, self.views, white, self.uses):
            _, pull = jax.vjp(prepared.shading.colour_map, ones)
            num = num + np.asarray(pull(v.target * use[..., None])[0])
            den = den + np.asarray(pull(jnp.asarray(w) * use[..., None])[0])
        self.set_seen(min_pixels)
        seen = self.seen
        if not seen.any():
            raise AlbedoMapError(f"no map texel is seen by at least min_pixels = {min_pixels:g} pixels' weight; "
                                 "lower min_pixels or map_size.")
        ratio = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
        fill = np.nanmedian(np.where(seen[..., None], ratio, np.nan).reshape(-1, 3), axis=0)
        ratio = np.where(self.free[..., None] & np.isfinite(ratio) & (ratio > 0), ratio, fill)
        return jnp.asarray(np.log(np.clip(ratio, 1e-4, 1e4)), self.dtype)

    def residuals(self, u, ell):
        return np.asarray(self._residuals({"u": u, "ell": ell}, self.views))

    def images(self, u, ell):
        return [np.asarray(i) for i in self._images({"u": u, "ell": ell}, self.views)]

    def set_seen(self, min_pixels):
        """``seen``: texels looked up with weight >= ``min_pixels`` (reported); ``free``: every texel
        any fitted pixel looks up (fitted: one held at a guess would bias its seen neighbours
        through the diffusion -- 4 to 6 standard errors next to the view's edge, measured)."""
        self.seen = self.cover >= min_pixels
        self.free = self.cover > 1e-6 * max(float(self.cover.max()), 1e-300)

    def solve(self, u, ell, max_steps, finish=True, tight=False):
        """Gauss-Newton from (u, ell): converged when a step gains less than 0.01 in chi^2 (or moves
        nothing), a step solved to cg_rtol where ``finish`` (else any: a round before the last);
        ``tight``: from the first step at cg_rtol (a round's loose end being finished)."""
        x = {"u": u, "ell": ell}
        cost = float(np.sum(self.residuals(u, ell) ** 2))
        cg_total, converged, n = 0, False, 0
        forcing = (0.0, -1.0) if tight else (0.0, 1.0)  # at cg_rtol, or the first step at FORCING_MAX
        diagonal, drift = None, 0.0
        for n in range(1, max_steps + 1):
            if diagonal is None or drift > DIAGONAL_DRIFT:
                diagonal, drift = self._diagonal_of(x, self.views), 0.0
            if finish and n == max_steps:
                forcing = (0.0, -1.0)  # the last step allowed: at cg_rtol
            delta, cg, _, size, eta = self._solve(x, self.views, jax.tree.map(jnp.zeros_like, x), True, 1.0,
                                                  diagonal, forcing=forcing)
            cg_total += int(cg)
            forcing = (float(size), float(eta))
            t = 1.0
            for _ in range(8):  # halving line search
                trial = jax.tree.map(lambda a, d: a + t * d, x, delta)
                new = float(np.sum(self.residuals(trial["u"], trial["ell"]) ** 2))
                if np.isfinite(new) and new <= cost:
                    break
                t *= 0.5
            else:
                if finish and float(eta) > self.cg_floor:  # a loose step: solve it again at the floor
                    forcing = (0.0, -1.0)
                    continue
                converged = True  # no decrease along the Gauss-Newton direction: at the minimum to rounding
                break
            x, gained, cost = trial, cost - new, new
            moved = max(float(jnp.max(jnp.abs(t * delta["u"]))), float(jnp.max(jnp.abs(t * delta["ell"]))))
            drift += moved
            if moved < 1e-6 or gained < 1e-2:
                if not finish or float(eta) <= self.cg_floor:
                    converged = True
                    break
                forcing = (0.0, -1.0)  # a loose step gained little: the next at the floor, cg_rtol
        return x["u"], x["ell"], n, cg_total, converged

    def variances(self, u, ell, errors, spacing, seed):
        """Diagonals of (J^T J)^-1 for the texels (H_m, W_m, 3; inf where unseen) and the mean free paths (3,)."""
        seen = self.free
        inf_u = np.where(seen[..., None], np.nan, np.inf) * np.ones(self.shape + (3,))
        if errors == "none":
            return np.where(seen[..., None], 0.0, np.inf) * np.ones(self.shape + (3,)), np.zeros(3), 0
        x = {"u": u, "ell": ell}
        if errors == "exact":
            flat, unravel = ravel_pytree(x)
            J = np.asarray(jax.jacfwd(lambda f: self._raw(unravel(f), self.views))(flat))
            keep = np.asarray(ravel_pytree({"u": jnp.asarray(np.repeat(seen[..., None], 3, -1), self.dtype),
                                            "ell": jnp.ones(3, self.dtype)})[0]) > 0
            cov = np.full(flat.size, np.inf)
            H = J[:, keep].T @ J[:, keep]
            cov[keep] = np.diag(np.linalg.inv(H))
            out = unravel(jnp.asarray(np.where(np.isfinite(cov), cov, 0.0)))
            var_u = np.where(seen[..., None], np.asarray(out["u"]), np.inf)
            return var_u, np.asarray(out["ell"]), 0
        # The mean free paths couple every texel of their channel: taken out exactly (Schur complement),
        # so that the probes see only the texels' own, local block B (the mean free paths held):
        # diag(A^-1)_u = diag(B^-1) + Y^2 / S with Y = B^-1 C and S = D - C^T Y. One solve of the
        # whole system on the mean free paths' unit vectors (the channels do not couple: all three
        # at once) gives x = A^-1 e_ell = (-Y / S, 1 / S): var(ell) = x_ell and Y^2 / S = x_u^2 / x_ell,
        # without forming S = D - C^T Y, a difference of near-equal numbers where the mean free path
        # is poorly constrained (it had put a channel's texel errors 1.5-1.9x too wide)
        zeros_u, ones_ell = jnp.zeros(self.shape + (3,), self.dtype), jnp.ones(3, self.dtype)
        diagonal = self._diagonal_of(x, self.views)
        coupled, cg, *_ = self._solve(x, self.views, {"u": zeros_u, "ell": ones_ell}, False, 1.0, diagonal,
                                        SCHUR_RTOL)
        var_ell = np.asarray(coupled["ell"])
        shared = (np.asarray(coupled["u"]) * seen[..., None]) ** 2 / var_ell
        cg_total = int(cg)
        rng = np.random.default_rng(seed)
        rows, cols = np.indices(self.shape)
        var_u = inf_u.copy()
        colours, probes = [], []
        for i in range(spacing):
            for j in range(spacing):
                # signs on the reported texels only: a barely seen one's large inverse entries would
                # scatter its seen neighbours' estimates (the estimate stays unbiased on any subset)
                colour = ((rows % spacing == i) & (cols % spacing == j) & self.seen)[..., None]
                if not colour.any():  # a zero probe (no CG step): one program for any pattern of seen texels
                    colours.append(colour)
                    probes.append(np.zeros(self.shape + (3,)))
                    continue
                colours.append(colour)
                probes.append(np.where(colour, rng.choice([-1.0, 1.0], size=self.shape + (3,)), 0.0))
        if probes:  # one CG solve per colour, all spacing^2 in one program (_Programs._solve_each)
            bs = {"u": jnp.asarray(np.stack(probes), self.dtype), "ell": jnp.zeros((len(probes), 3), self.dtype)}
            values, cg, _ = self.programs.solve_each(x, self.data, self.views, bs, jnp.asarray(ERROR_RTOL, self.dtype),
                                                     diagonal)
            cg_total += int(cg)
            for colour, signs, value in zip(colours, probes, np.asarray(values["u"])):
                var_u = np.where(np.broadcast_to(colour, var_u.shape), signs * value, var_u)
        return var_u + shared, var_ell, cg_total
