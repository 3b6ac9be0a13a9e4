r"""Recover a homogeneous material from a linear photo of a scene whose geometry, camera and lights are known.

Inverse rendering: the photo's pixels :math:`I_p` are fitted by :math:`g\,L_p(\theta)`, the
renderer's linear radiance of the scene with the material's :math:`\sigma_a, \sigma_s'` per
channel (:math:`\theta = \ln\sigma_a, \ln\sigma_s'`, so both stay positive) times an unknown
exposure gain :math:`g` (photos have no absolute scale; ``gain=False`` holds it at 1 for a
calibrated camera). The residuals :math:`(g L_p - I_p)/s_p` are whitened by the photo's noise
:math:`s_p` (given, or ``noise`` times the pixel value) and minimised by optimistix's
Levenberg-Marquardt in one jitted call.

What is fixed during a fit is computed once: the rasterisation, the shadow maps, the texel
geometry and, for texture-space diffusion, the blur itself. With the Gaussian variances held
fixed the frame is linear in the Gaussian weights (d'Eon 2007 sec. 5) and its single
scattering in the albedo: the renderer keeps it so, as :func:`jsss.render.linear_frame`
(the same stages and composition as :func:`jsss.render.render`), and one model evaluation is
the profile fit of the weights (:func:`jsss.render.profiles.render_profile`, differentiable
in the medium) and :meth:`jsss.render.LinearFrame.radiance`. The variances are planned for
the starting material; if the fitted profile is not represented on them to the plan's
accuracy, they are re-planned and the fit is repeated from
there (at most ``replans`` times); so are the oblique-incidence law that scales the irradiance
and the depth at which point lights are read (:mod:`jsss.diffusion.incidence`), which depend on
the medium (their change within the last round is not in the Jacobian). The objective is
each estimate's misfit on the plan made for it, which jumps where the plan does: a round whose
estimate fits worse on its own plan than the round's start did on the start's moved along the
plan's error, not the photo's, and is not kept (the start is the estimate). The exit law
(:mod:`jsss.diffusion.exit_law`) follows the albedo in every evaluation. The pixel methods
(Lambert, normal filtering, image-space) are differentiated through their whole frame.

A photo taken through the real surface holds the specular highlight (Beckmann lobe, Cook-Torrance;
:func:`jsss.render.shading.specular_radiance`): its pixels are the brightest and carry the
smallest errors, so a roughness guessed wrong steers the medium. ``highlight`` fits the roughness
as one more parameter (the lobe is the frame's one term in it, recomputed from the fixed
geometry and lights at each step), masks the pixels the lobe may dominate, or holds it as before;
the result says which (:attr:`RenderFit.highlight`).

What the image constrains is reported, not assumed (:mod:`fitting.statistics`): the covariance
:math:`s^2 (J^T J)^{-1}` at the solution, with :math:`s^2 = \max(1, \chi^2/(m - n))` so that a
model that cannot fit the photo (chi^2 per degree of freedom above 1) widens its errors
rather than claiming noise-level precision, plus the covariance of the renderer's own error
(``model_error``, a relative error in each channel's light that no photo's noise shows, and the
plan's own where the fit re-planned, propagated through the same linearised solution), and a
warning for each parameter whose relative standard error exceeds ``unconstrained`` (e.g. the mean free path of a uniformly lit object,
or any spread under Lambert, which has none). The artist's parameters -- the total diffuse
reflectance :math:`R_d` (the profile model's, per unit entering flux at normal incidence) and
the mean free path :math:`1/\sigma_t'` -- are derived with their errors by the delta method.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from scipy import ndimage

from fitting.statistics import covariance, error_scale, reduced_chi2, standard_errors
from jsss import transport
from jsss.diffusion import dipole
from jsss.diffusion.incidence import incidence_ratio
from jsss.medium import Medium
from jsss.numerics import warn_if_low_precision
from jsss.render import (
    LinearFrame,
    Material,
    Method,
    Pass,
    Scene,
    camera_buffers,
    deposit_change,
    distance_to_rim,
    first_leg_change,
    last_leg_change,
    linear_frame,
    plan_scene,
    render_params,
)
from jsss.render.environment import EnvironmentGeometry
from jsss.render.profiles import render_profile
from jsss.render.shading import specular_radiance

__all__ = ["GAIN_PINNED", "MODEL_ERROR", "RenderFit", "RenderFitError", "estimate_noise", "fit_pixels", "fit_render",
           "gain_from_reference"]


class RenderFitError(ValueError):
    """The scene or the photo cannot be fitted; the message says which and why."""


@dataclass(frozen=True, eq=False)
class RenderFit:
    """Result of :func:`fit_render`; per-channel arrays have shape (3,).

    Attributes
    ----------
    medium : Medium
        The estimate (eta is the scene's, held fixed).
    sigma_a_err, sigma_s_prime_err : ndarray [1/mm]
        One-sigma standard errors.
    gain, gain_err : float
        The exposure gain (photo / linear radiance) and its error (0 when held; inf where the
        photo could not resolve it from R_d, :data:`GAIN_PINNED`).
    reflectance, reflectance_err : ndarray
        Total diffuse reflectance R_d of the profile model at the estimate, and its error.
    mean_free_path, mean_free_path_err : ndarray [mm]
        :math:`1/(\\sigma_a + \\sigma_s')` and its error.
    covariance : ndarray (n, n)
        Of the fitted parameters ``parameter_names`` (logarithms of sigma_a, sigma_s', gain): the
        photo's noise's and the renderer's own error's (``model_error``), summed.
    chi2_reduced : float
        chi^2 per degree of freedom of the whitened residuals (about 1 when model and noise fit;
        with Huber's loss, their median square over its Gaussian value 0.4549, which outliers
        do not move).
    steps : int; converged : bool
        Solver steps (all outer rounds); the solver met its tolerances, every parameter is
        finite and has a finite standard error (the image constrains it), and no channel ran
        to the edge of the parameters (an albedo' above 0.9999 from a start below it).
    n_pixels : int
        Pixels used (the mask).
    method, profile_model : str
        How the photo was rendered during the fit.
    image : ndarray (H, W, 3)
        The fitted render, gain applied (0 off the object).
    mask : ndarray (H, W) of bool
        The pixels fitted.
    warnings : tuple of str
        Unconstrained parameters, a poor fit.
    history : tuple of str
        What each round re-planned, and why.
    sigma : ndarray (H, W, 3)
        Each pixel's standard error as fitted (given, or estimated from the photo).
    gain_unresolved : bool
        The gain was fitted and the photo did not pin it (:data:`GAIN_PINNED`): R_d, sigma_a and
        the gain are one direction without finite errors, not measurements.
    highlight : str
        What was done with the specular highlight (fit_render's ``highlight``): ``"mask"`` (its
        pixels left out), ``"fit"`` (its roughness fitted), ``"model"`` (rendered at the scene's
        roughness and held) or ``"none"`` (no surface reflection in the fit: ``specular=False``,
        or the scene's specular weight is 0).
    highlight_pixels : int
        Pixels left out as the highlight's (``"mask"``; 0 otherwise).
    roughness, roughness_err : float
        The Beckmann roughness m of the fit's highlight (fitted with ``"fit"``, else the scene's,
        error 0).
    model_error : float
        The renderer's relative error in each channel's subsurface light that the errors above
        include (fit_render's ``model_error``; 0: the photo's noise alone).
    """

    medium: Medium
    sigma_a_err: np.ndarray
    sigma_s_prime_err: np.ndarray
    gain: float
    gain_err: float
    reflectance: np.ndarray
    reflectance_err: np.ndarray
    mean_free_path: np.ndarray
    mean_free_path_err: np.ndarray
    covariance: np.ndarray
    parameter_names: tuple
    chi2_reduced: float
    steps: int
    converged: bool
    n_pixels: int
    method: str
    profile_model: str
    image: np.ndarray
    mask: np.ndarray
    warnings: tuple = ()
    history: tuple = ()
    sigma: np.ndarray | None = None
    gain_unresolved: bool = False
    highlight: str = "model"
    highlight_pixels: int = 0
    roughness: float = float("nan")
    roughness_err: float = 0.0
    model_error: float = 0.0

    def as_dict(self) -> dict:
        """JSON-ready summary (lists per channel)."""
        listed = lambda a: [float(x) for x in np.broadcast_to(np.asarray(a, float), (3,))]
        return {"sigma_a": listed(self.medium.sigma_a), "sigma_a_err": listed(self.sigma_a_err),
                "sigma_s_prime": listed(self.medium.sigma_s_prime), "sigma_s_prime_err": listed(self.sigma_s_prime_err),
                "eta": listed(self.medium.eta), "gain": float(self.gain), "gain_err": float(self.gain_err),
                "reflectance": listed(self.reflectance), "reflectance_err": listed(self.reflectance_err),
                "mean_free_path_mm": listed(self.mean_free_path), "mean_free_path_err_mm": listed(self.mean_free_path_err),
                "chi2_reduced": float(self.chi2_reduced), "steps": int(self.steps), "converged": bool(self.converged),
                "pixels": int(self.n_pixels), "method": self.method, "profile_model": self.profile_model,
                "parameters": list(self.parameter_names), "covariance": np.asarray(self.covariance).tolist(),
                "warnings": list(self.warnings), "history": list(self.history), "highlight": self.highlight,
                "highlight_pixels": int(self.highlight_pixels), "roughness": float(self.roughness),
                "roughness_err": float(self.roughness_err), "model_error": float(self.model_error)}


def gain_from_reference(scene: Scene, photo, reflectance: float = 0.99, *, mask=None,
                        saturation: float | None = None) -> tuple[float, float]:
    r"""The photo's exposure gain from a white (or grey) Lambertian target of known reflectance.

    ``scene`` holds the target's geometry, as photographed with the same camera settings and
    lights as the material's photo: a card in the same frame (give the same photo, and ``mask``
    its pixels) or a photo of its own. Its material is ignored: the target renders as an ideal
    diffuser of albedo ``reflectance`` (radiance :math:`\rho E / \pi`, no specular: the index-
    matched, non-absorbing medium, whose total reflectance is exactly 1, under Lambert). The
    gain is the median of photo over render across the target's pixels (robust to hot pixels
    and a path tracer's fireflies), and its relative standard error
    :math:`1.253 \cdot 1.4826\,\mathrm{MAD} / (\mathrm{median} \sqrt{n})` (the median's efficiency
    for Gaussian scatter).

    Returns
    -------
    gain, relative_error : float
        Pass both to :func:`fit_render` (``gain=``, ``gain_err=``).

    Raises
    ------
    RenderFitError
        A reflectance outside (0, 1], a photo that does not match the camera, fewer than 10
        target pixels, or a target that renders black (unlit).
    """
    reflectance = float(reflectance)
    if not (np.isfinite(reflectance) and 0 < reflectance <= 1):
        raise RenderFitError(f"reflectance must lie in (0, 1] (0.99 for Spectralon, 0.18 for a grey card); "
                             f"got {reflectance:g}.")
    if not scene.lights:
        raise RenderFitError(f"{scene.source}: the reference scene has no lights; it needs the material photo's lights.")
    photo = np.asarray(photo, float)
    white = Material("white reference", np.ones(3), medium=Medium(np.zeros(3), np.ones(3), np.ones(3)),
                     specular=0.0, roughness=scene.material.roughness)
    target_scene = dataclasses.replace(scene, material=white)
    plan = plan_scene(target_scene, method=Method.LAMBERT)
    for decision in plan.decisions:
        if decision.on:
            plan = plan.replace(decision.name, False, "a white diffuser: albedo times irradiance")
    from jsss.render import render

    model = reflectance * np.asarray(render(target_scene, plan, dtype=jnp.float64).radiance)
    use = fit_pixels(target_scene, photo, mask=mask, saturation=saturation)
    use &= np.all(model > 0, axis=-1)
    if use.sum() < 10:
        raise RenderFitError(f"{scene.source}: only {int(use.sum())} lit pixels of the reference target (needs 10); "
                             "is the camera looking at it, and is it lit?")
    ratio = (photo[use] / model[use]).reshape(-1)
    gain = float(np.median(ratio))
    spread = 1.4826 * float(np.median(np.abs(ratio - gain)))
    return gain, max(1.2533 * spread / (gain * np.sqrt(ratio.size)), 1e-12)


def fit_pixels(scene: Scene, photo, *, mask=None, saturation: float | None = None,
               min_cos: float = 0.2, rim_mm: float = 0.0) -> np.ndarray:
    """The pixels a fit uses: the object as the scene's camera sees it, without its silhouette.

    A pixel counts when the object covers it and its 8 neighbours (a silhouette pixel is
    partly background, which no render of the object predicts), the surface faces the camera
    with a cosine of at least ``min_cos`` (grazing pixels are the most sensitive to the
    mesh's facets), no channel reaches ``saturation`` (if given), it lies at least ``rim_mm``
    from an open surface's rim (what lies beyond a rim is not in the scene: light that reaches
    it leaves in the render, and meets whatever the real object goes on as in the photo), and
    ``mask`` (optional, (H, W), true = use) allows it.

    Raises
    ------
    RenderFitError
        The photo is not (H, W, 3) at the camera's resolution, the mask does not match, or a
        pixel to be fitted is NaN or infinite.
    """
    photo = np.asarray(photo)
    cam = scene.camera
    if photo.ndim != 3 or photo.shape[2] != 3:
        raise RenderFitError(f"photo: expected an RGB image (H, W, 3); got shape {photo.shape}.")
    if photo.shape[:2] != (cam.height, cam.width):
        raise RenderFitError(f"photo: {photo.shape[1]} x {photo.shape[0]} pixels, but the scene's camera renders "
                             f"{cam.width} x {cam.height}; set [camera] resolution to the photo's size.")
    buffers = camera_buffers(scene.mesh, cam)
    inside = ndimage.binary_erosion(buffers.coverage >= 1, structure=np.ones((3, 3), bool), border_value=1)
    facing = (buffers.normal * buffers.view).sum(-1) >= min_cos
    use = inside & facing
    if not (rim_mm >= 0 and np.isfinite(rim_mm)):
        raise RenderFitError(f"rim_mm must be a finite distance >= 0 [mm]; got {rim_mm!r}.")
    if rim_mm > 0:
        use &= distance_to_rim(scene.mesh, buffers.position) >= rim_mm
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != use.shape:
            raise RenderFitError(f"mask: {mask.shape[1]} x {mask.shape[0]} pixels, but the photo is "
                                 f"{photo.shape[1]} x {photo.shape[0]}.")
        use &= mask.astype(bool)
    bad = use & ~np.isfinite(photo).all(-1)
    if bad.any():
        y, x = np.argwhere(bad)[0]
        raise RenderFitError(f"photo: {int(bad.sum())} pixels on the object are NaN or infinite (the first at x = {x}, "
                             f"y = {y}); repair them or exclude them with a mask.")
    if saturation is not None:
        use &= ~(photo >= saturation).any(-1)
    return use


# The range a fit's medium may take: sigma_s' [1/mm] and sigma_a / sigma_s' (the transport
# tables end at 1e3). A photo that does not constrain a channel (ketchup's blue, whose light
# hardly diffuses back) let Levenberg-Marquardt run to sigma_a / sigma_s' = 1e36 there; the
# next plan then raised and the render overflowed (a path-traced ketchup photo, 2026-12-07).
# Beyond the range the model is held at its edge: the residuals stop moving, so that
# parameter gets no finite error, and the fit says where it ran (its warnings).
SCATTERING_RANGE = (1e-4, 1e4)
ABSORPTION_RATIO_RANGE = (1e-9, 999.0)


def _held_in_range(theta):
    """``theta[:6]`` (ln sigma_a, ln sigma_s') clipped to the fit's range (see above)."""
    ln_scattering = jnp.clip(theta[3:6], *np.log(SCATTERING_RANGE))
    ln_absorption = jnp.clip(theta[:3], ln_scattering + np.log(ABSORPTION_RATIO_RANGE[0]),
                             ln_scattering + np.log(ABSORPTION_RATIO_RANGE[1]))
    return jnp.concatenate([ln_absorption, ln_scattering])


def _medium(theta, eta) -> Medium:
    """The medium of the log-coefficients ``theta[:6]`` (ln sigma_a, ln sigma_s'), held in the fit's range."""
    held = _held_in_range(theta)
    return Medium(jnp.exp(held[:3]), jnp.exp(held[3:6]), eta)


def _artist(theta, profile_model, g, eta):
    """R_d (3,) and mean free path (3,) [mm] of the log-coefficients ``theta[:6]``."""
    medium = _medium(theta, eta)
    total = (transport.total_reflectance(medium, g=g) if profile_model == "transport"
             else dipole.total_reflectance(medium))
    return jnp.concatenate([total, 1.0 / (medium.sigma_a + medium.sigma_s_prime)])


def _profile_radii(variances) -> np.ndarray:
    """Where the render profile is fitted [mm]: the narrowest Gaussian's core to the widest's tail."""
    v = np.asarray(variances, float)
    return np.geomspace(np.sqrt(v.min()) / 30, np.sqrt(v.max()) * 8, 600)


def _texture_radiance(medium, data, profile_model: str, g: float):
    """Linear radiance (H, W, 3) of a texture-space fit's scene for ``medium`` (variances fixed):
    the weights the render profile fits for it on the frame's variances, and the reduced albedo,
    through :meth:`jsss.render.LinearFrame.radiance`. ``data = (frame, radii)``."""
    frame, radii = data
    material = Material("fit", np.ones(3), medium=medium, profile_model=profile_model, g=g)
    weights = render_profile(material, frame.variances, radii=radii, medium=medium).weights
    albedo = medium.sigma_s_prime / (medium.sigma_a + medium.sigma_s_prime)
    return frame.radiance(weights, albedo, medium=medium)  # the irradiance's laws follow the medium


def _follows_laws(data) -> bool:
    """Whether the fit's data hold a texture-space frame that follows the irradiance's laws."""
    frames = [leaf for leaf in jax.tree.leaves(data, is_leaf=lambda x: isinstance(x, LinearFrame))
              if isinstance(leaf, LinearFrame)]
    return bool(frames) and frames[0].law_light is not None


@functools.lru_cache(maxsize=16)
def _texture_render(profile_model: str, g: float):
    """One function object per configuration, so that the jitted solve is compiled once for it."""
    return lambda medium, data: _texture_radiance(medium, data, profile_model, g)


LAW_REPLAN = 0.002  # re-plan when the oblique-incidence law, the deposit depth or a leg's step moves a pixel by more:
# at 1 % a held law 0.78 % off put marble's sigma_a +33 % (4.3 stated errors) in the tests' gain fit
LAW_FOLLOWED = 0.05  # the same for the irradiance's two laws where texture space's frame follows them
# (jsss.render.linear_frame, read at the pixel): what it misses is second order, 0.08 % RMS per pixel
# on the ketchup plane after a 4.2 % move under the lamp (1.9 % with the law held)


def _incidence_moved(before: Scene, after: Scene) -> float:
    """Largest relative change of the oblique-incidence law between two scenes' media."""
    cosines = jnp.linspace(0.05, 1.0, 20)
    old = np.asarray(incidence_ratio(before.material.medium, cosines))
    new = np.asarray(incidence_ratio(after.material.medium, cosines))
    return float(np.max(np.abs(new / old - 1)))


HUBER_K = 1.345  # Huber's threshold in standard errors: 95 % of least squares' efficiency for Gaussian noise


def _huber(r):
    """Residuals whose squares sum to Huber's loss (times 2): ``r`` within +-k, beyond it
    ``sign(r) sqrt(2 k |r| - k^2)``, which grows as sqrt|r| (continuous, with a continuous slope)."""
    magnitude = jnp.abs(r)
    outer = jnp.sqrt(jnp.maximum(2 * HUBER_K * magnitude - HUBER_K**2, HUBER_K**2))  # double where: finite slope
    return jnp.where(magnitude <= HUBER_K, r, jnp.sign(r) * outer)


def _local_level(photo, use, pixels: float = 1.0) -> np.ndarray:
    """The photo averaged over its neighbours within the fitted pixels: a Gaussian of ``pixels``
    standard deviation, the pixel itself left out (its own noise would make a level it is
    weighted by lean its way: -1.3 % in a 20 %-noise fit with it in) and the background too
    (normalised convolution at the object's outline)."""
    impulse = np.zeros(2 * int(4 * pixels + 0.5) + 1)  # the filter's own reach (truncate=4)
    impulse[impulse.size // 2] = 1.0
    own = ndimage.gaussian_filter1d(impulse, pixels)[impulse.size // 2] ** 2  # its weight on the pixel itself
    weight = use.astype(float)
    values = np.where(use[..., None], photo, 0.0)
    summed = ndimage.gaussian_filter(values, (pixels, pixels, 0)) - own * values
    total = ndimage.gaussian_filter(weight, pixels) - own * weight
    return summed / np.maximum(total, 1e-12)[..., None]


def provisional_noise(photo, use, relative: float | None = None) -> np.ndarray:
    r"""Each pixel's standard error before any fit: ``relative`` times the pixel's local level, or
    (``None``) :func:`estimate_noise` of the photo's own adjacent differences, binned by the level.

    The level is the photo averaged over a pixel's neighbours (:func:`_local_level`), not the
    pixel's own noisy value: with :math:`\sigma \propto` the noisy value, a pixel pulled dark by
    its noise weighs more than one pulled bright, and the fit comes out dark (Neyman's
    :math:`\chi^2`). Estimated, the noise also sets Huber's threshold at the photo's own scale: a
    provisional 5 % of the pixel value on a path-traced photo with 16-28 % noise per pixel made
    Huber's loss nearly a median fit: with both, the scale of the truth's model that the loss
    preferred on the ketchup plane's path-traced red (Mitsuba, 28 % noise per pixel, heavy
    tailed) was 0.87; with this noise 0.97, beside the photo's mean over the model's, 0.98 (the
    renderer's own error). Fewer than 200 adjacent fitted pixels (too few to estimate): 5 % of
    the level.
    """
    level = np.abs(_local_level(photo, use))
    floor = np.maximum(0.01 * np.percentile(level[use], 99, axis=0), 1e-300)
    level = np.maximum(level, floor)  # dark pixels: 1 % of the channel's bright end
    if relative is not None:
        return relative * level
    try:
        return np.maximum(estimate_noise(photo, level, use), 1e-3 * level)
    except RenderFitError:
        return 0.05 * level


def _pixel_residuals(model, photo, mask, inverse_sigma, block, robust):
    """The photo's whitened residuals (flat), over ``block`` x ``block`` tiles, Huber-transformed
    with ``robust``: ``model`` is the frame times the gain."""
    pixels = (_block_sums((model - photo) * mask, block) * inverse_sigma).reshape(-1)
    return _huber(pixels) if robust else pixels


@functools.lru_cache(maxsize=16)
def _residual_fn(render, fit_gain, block, prior, robust=False, fit_roughness=False):
    """Whitened residuals of the photo (Huber-transformed with ``robust``); with ``prior``, one
    more: the fitted ln gain's distance from a reference's, in units of that reference's relative
    error. ``exposure`` (in ``args``) holds the held gain, the reference's ln gain and its inverse
    relative error. With ``fit_roughness`` the last parameter is the highlight's ln roughness,
    passed to ``render`` (:func:`_with_highlight`)."""
    def residuals(theta, args):
        data, photo, mask, inverse_sigma, eta, exposure = args
        medium = _medium(theta, eta)
        gain = jnp.exp(theta[6]) if fit_gain else exposure[0]
        image = render(medium, data, jnp.exp(theta[-1])) if fit_roughness else render(medium, data)
        pixels = _pixel_residuals(gain * image, photo, mask, inverse_sigma, block, robust)
        if not prior:
            return pixels
        return jnp.concatenate([pixels, ((theta[6] - exposure[1]) * exposure[2])[None]])
    return residuals


# With the gain fitted and no reference, the gain counts as pinned by the photo (the specular
# highlight, whose Fresnel reflectance is known physics, or the profile's shape) only where its
# relative error is below this; else brightness is gain x R_d, one direction the photo cannot
# resolve (issue 36: a subsurface-only photo gave gain 11.8 +- 5.4 and R_d 0.063 for a white
# stone of 0.8, 26 errors off, reported as converged).
GAIN_PINNED = 0.05

# The renderer's own error in a channel's subsurface light, as a relative standard error: the RMS
# of (jsss / path tracer - 1) over the channel sums of its default frames against Mitsuba 3,
# index-matched (docs/benchmarks/transport_truth.md, 2026-12-05: five calibration scenes and the
# two examples, 21 channel sums from 0.953 to 1.016; RMS 1.5 %). A fit cannot know R_d better
# than its renderer draws it: through the marble sphere's dielectric the errors of the photo's
# noise alone were 0.4 % and R_d came out +1.2 to +1.7 % (z up to 4.6).
MODEL_ERROR = 0.015


def _model_error_covariance(J, slopes, model_error):
    r"""The parameters' covariance from the renderer's error in each channel's subsurface light.

    A renderer whose channel ``c`` is off by a factor :math:`1 + \epsilon_c` moves the
    least-squares solution by :math:`\delta\theta = -(J^T J)^{-1} J^T d_c\,\epsilon_c`, where
    :math:`d_c` (column ``c`` of ``slopes``) is the slope of the whitened residuals in
    :math:`\ln(1 + \epsilon_c)` (linearised, as the statistical errors are). With independent
    :math:`\epsilon_c` of standard error ``model_error`` the covariance is
    :math:`\epsilon^2 \sum_c \delta\theta_c \delta\theta_c^T`, added to the noise's. With the
    gain fitted and nothing else to tell them apart, the shift goes into the gain; with a
    reference's gain (its prior), into R_d and sigma_a.
    """
    return model_error**2 * _shifts_covariance(J, slopes)


def _shifts_covariance(J, moves):
    r"""Sum of :math:`\delta\theta_j \delta\theta_j^T` over the columns ``moves`` (m, k) of changes
    to the whitened residuals, :math:`\delta\theta_j = -(J^T J)^{-1} J^T d_j`: the linearised
    solution's shifts, on the directions the photo sees (the others are infinite already)."""
    inverse, _ = covariance(J, 1.0)
    shift = -inverse @ (np.asarray(J).T @ np.asarray(moves))
    return shift @ shift.T


def _model_error_slopes(theta, args, image, specular, fit_gain, block, robust, prior):
    """(m, 3): the slopes of fit_render's residuals in the log of each channel's subsurface light
    (``image`` without its ``specular`` part), the rest held: :func:`_model_error_covariance`'s
    :math:`d_c`."""
    _, photo, mask, inverse_sigma, _, exposure = args
    gain = jnp.exp(theta[6]) if fit_gain else exposure[0]
    subsurface = image - specular

    def residuals(log_scale):
        model = jnp.exp(log_scale) * subsurface + specular
        pixels = _pixel_residuals(gain * model, photo, mask, inverse_sigma, block, robust)
        return jnp.concatenate([pixels, jnp.zeros(int(prior), pixels.dtype)])  # the reference's row does not move

    return np.asarray(jax.jacfwd(residuals)(jnp.zeros(3, image.dtype)))


def _plan_error_covariance(J, theta, args, image, difference, fit_gain, block, robust, prior):
    r"""The parameters' covariance from the plan's own error, observed: ``difference`` (H, W, C)
    is the estimate's frame under the last re-plan less its frame under the plan before, two
    plans that each claim the fit's accuracy (not the first re-plan's: that plan was the start's,
    which may be far from any estimate). As :func:`_model_error_covariance`, it moves the
    solution by :math:`-(J^T J)^{-1} J^T d`, with :math:`d` the whitened residuals' change, whose
    outer product is the covariance: the estimate's own plan may be as wrong as two plans
    disagree. On the ketchup plane through its dielectric, plans
    that each claimed 0.1 % raised the chi^2 at one estimate by 60-260 (of 34500) and sent the red
    mean free path from 5.6 to 10 mm over three rounds, while its stated error was 3-8 %."""
    _, photo, mask, inverse_sigma, _, exposure = args
    gain = jnp.exp(theta[6]) if fit_gain else exposure[0]

    def whitened(model):
        pixels = _pixel_residuals(gain * model, photo, mask, inverse_sigma, block, robust)
        return np.concatenate([np.asarray(pixels), np.zeros(int(prior))])  # the reference's row does not move

    return _shifts_covariance(J, (whitened(image + jnp.asarray(difference, image.dtype)) - whitened(image))[:, None])


NO_EXPOSURE = ("the photo's exposure is unknown, and a photo's brightness is gain x R_d: give a reference (a photo "
               "of a white target of known reflectance: fitting.render.gain_from_reference, jsss-render fit "
               "--reference-scene/--reference-photo), the camera's gain (gain=G, --gain G; 1 for calibrated "
               "radiance, --no-gain), or fit it explicitly (gain='fit', --fit-gain), which leaves R_d and the gain one "
               "direction unless the photo pins the gain")


def _exposure(gain, gain_err):
    """``(fit_gain, start, prior)`` from fit_render's ``gain`` and ``gain_err``: whether ln gain is a
    parameter, the held or starting gain, and whether a reference's error ties it down."""
    if gain is None:
        raise RenderFitError(NO_EXPOSURE + ".")
    if isinstance(gain, str):
        if gain != "fit":
            raise RenderFitError(f"gain must be a positive number, 'fit' or None; got {gain!r}.")
        return True, None, False
    if isinstance(gain, bool | np.bool_):  # before 2026-12-04: True fitted it, False held it at 1
        return (True, None, False) if gain else (False, 1.0, False)
    value, error = float(gain), float(gain_err)
    if not (np.isfinite(value) and value > 0):
        raise RenderFitError(f"gain must be > 0 (photo value per unit linear radiance); got {value:g}.")
    if not (np.isfinite(error) and error >= 0):
        raise RenderFitError(f"gain_err must be >= 0 (the gain's relative standard error); got {error:g}.")
    return error > 0, value, error > 0


def estimate_noise(residual, expected, use) -> np.ndarray:
    r"""Each pixel's standard error from the residuals of a first fit: the variance
    :math:`a + b\,\mu + c\,\mu^2` in the expected value :math:`\mu`, fitted per channel: read
    noise, shot noise, and noise proportional to the signal (a path tracer's at a fixed sample
    count, a relative error).

    The variance is read from the differences of horizontally and vertically adjacent residuals,
    :math:`\mathrm{Var}(d_p - d_q) = \sigma_p^2 + \sigma_q^2`, so a misfit that is smooth over a
    pixel (a biased model) does not pass for noise and still shows in chi^2; each of 12 bins of
    :math:`\mu` takes its variance from the median absolute difference (1.4826 MAD: robust to
    fireflies and hot pixels), and :math:`a, b, c \ge 0` are fitted to the bins by non-negative least
    squares in relative terms (each bin's variance is known to about :math:`1/\sqrt{n}` of itself).

    Parameters
    ----------
    residual, expected : ndarray (H, W, C)
        Photo minus fitted render, and the fitted render (gain applied).
    use : ndarray (H, W) of bool
        The fitted pixels.

    Returns
    -------
    ndarray (H, W, C): the standard error of every pixel (positive everywhere).

    Raises
    ------
    RenderFitError
        Fewer than 200 adjacent pairs of fitted pixels: too few to estimate a noise model (give
        the noise instead).
    """
    from scipy.optimize import nnls

    pairs = [(np.s_[:, 1:], np.s_[:, :-1]), (np.s_[1:, :], np.s_[:-1, :])]
    both = [use[a] & use[b] for a, b in pairs]
    if sum(int(m.sum()) for m in both) < 200:
        raise RenderFitError("too few adjacent fitted pixels (under 200) to estimate the photo's noise; give it "
                             "(noise=..., --noise).")
    sigma = np.empty_like(expected, dtype=float)
    for c in range(expected.shape[-1]):
        diff = np.concatenate([(residual[a][..., c] - residual[b][..., c])[m] for (a, b), m in zip(pairs, both)])
        level = np.concatenate([(0.5 * (expected[a][..., c] + expected[b][..., c]))[m] for (a, b), m in zip(pairs, both)])
        order = np.argsort(level)
        rows, weights = [], []
        for chunk in np.array_split(order, 12):
            d = diff[chunk]
            spread = 1.4826 * np.median(np.abs(d - np.median(d)))
            mu = max(float(np.median(level[chunk])), 0.0)
            rows.append((1.0, mu, mu**2, spread**2 / 2))
            weights.append(np.sqrt(chunk.size))
        rows = np.asarray(rows)
        weights = np.asarray(weights)
        # Relative weights: each bin's variance is known to about 1/sqrt(n) of itself, whatever its size.
        scale = weights / np.maximum(rows[:, 3], 1e-300)
        (a, b, q), _ = nnls(rows[:, :3] * scale[:, None], rows[:, 3] * scale)
        floor = 1e-6 * max(float(rows[:, 3].max()), 1e-300)
        mu = np.maximum(expected[..., c], 0.0)
        sigma[..., c] = np.sqrt(np.maximum(a + b * mu + q * mu**2, floor))
    return sigma


def _block_sums(image, block: int):
    """Sums over ``block`` x ``block`` tiles (H and W multiples of it); the image itself for 1."""
    if block == 1:
        return image
    h, w = image.shape[0] // block, image.shape[1] // block
    return image[:h * block, :w * block].reshape(h, block, w, block, -1).sum((1, 3))


def _plan_changes(plan, next_plan, scene, next_scene, data) -> list[str]:
    """What a fit's re-plan for its estimate (``next_plan`` for ``next_scene``) changes against the
    round's ``plan`` for ``scene``, in words; empty when the round's fixed passes still hold.
    ``data``: the round's model data (whether its frame follows the irradiance's laws)."""
    changed = [d.name for d, e in zip(plan.decisions, next_plan.decisions) if d.on != e.on]
    if next_plan.method != plan.method or next_plan.texture_size != plan.texture_size:
        changed.append("method or texture size")
    elif plan.method == Method.TEXTURE_SPACE:
        if len(next_plan.variances) != len(plan.variances):
            changed.append("number of Gaussians")
        elif (moved := np.max(np.abs(np.log(next_plan.variances / plan.variances)))) > 0.1:
            changed.append(f"Gaussian variances (moved by up to {100 * moved:.0f} %)")
        # The fixed passes hold the irradiance scaled by the round's own laws; a move below
        # LAW_REPLAN changes every pixel by less than that. At 1 % (a round of blurs fewer;
        # the test suite's fits were 1.5-3x faster) a held law biased the gain fit by 4 errors.
        # The frame follows the irradiance's laws itself, read at each pixel, except under
        # translucent shadow maps (jsss.render.linear_frame): a move re-plans past LAW_FOLLOWED.
        laws = LAW_FOLLOWED if _follows_laws(data) else LAW_REPLAN
        if plan.on(Pass.OBLIQUE_INCIDENCE) and (moved := _incidence_moved(scene, next_scene)) > laws:
            changed.append(f"oblique-incidence law (moved by up to {100 * moved:.2f} %)")
        if plan.on(Pass.DEPOSIT_DEPTH) and (moved := abs(deposit_change(next_scene)[0]
                                                      - deposit_change(scene)[0])) > laws:
            changed.append(f"deposit depth (irradiance under the lamp moved by {100 * moved:.2f} %)")
        if plan.on(Pass.LAST_LEG) and (moved := abs(last_leg_change(next_scene)[0]
                                                 - last_leg_change(scene)[0])) > LAW_REPLAN:
            changed.append(f"last leg (its change under the lamp or at the rim moved by {100 * moved:.2f} %)")
        if plan.on(Pass.FIRST_LEG) and (moved := abs(first_leg_change(next_scene)[0]
                                                  - first_leg_change(scene)[0])) > LAW_REPLAN:
            changed.append(f"first leg (its change at the rim moved by {100 * moved:.2f} %)")
    return changed


@eqx.filter_jit
def _cost(residuals, theta, args):
    """The fit's objective at ``theta``: the sum of squared (whitened, robust) residuals."""
    r = residuals(theta, args)
    return jnp.sum(r * r)


@eqx.filter_jit
def _jacobian(residuals, theta, args):
    return jax.jacfwd(residuals)(theta, args)


@eqx.filter_jit
def _solve(residuals, theta0, args, *, max_steps, rtol, atol):
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    sol = optx.least_squares(residuals, solver, theta0, args=args, max_steps=max_steps, throw=False)
    jac = jax.jacfwd(residuals)(sol.value, args)
    return sol.value, sol.stats["num_steps"], sol.result == optx.RESULTS.successful, jac


def _model_for(scene, plan, dtype, profile_model, g, *, shading=False):
    """The forward model ``render(medium, data)`` and its data for one plan (and, with
    ``shading``, the camera pass's :class:`~jsss.render.methods.PixelShading`, third).

    Texture space: the renderer's linear frame (:func:`jsss.render.linear_frame`; its blur in
    float32, whose images are good to 1e-7, far below any photo's noise, at half the time;
    the solve itself stays in ``dtype``). The pixel methods: their whole frame, differentiated
    through (normal filtering's filter and image-space's sampling disc fixed at the plan's
    material by ``prepare``)."""
    method = plan.method_config
    if plan.method == Method.TEXTURE_SPACE:
        prepared = method.prepare(scene, plan)
        frame = linear_frame(scene, plan, dtype=dtype, blur_dtype=jnp.float32, prepared=prepared)
        model = _texture_render(profile_model, g), (frame, jnp.asarray(_profile_radii(plan.variances), dtype))
        return (*model, prepared.shading) if shading else model
    prepared = method.prepare(scene, plan, render_params(scene, plan, dtype=dtype))
    radii = _profile_radii(plan.variances)

    def render(medium, data):
        return method.radiance(render_params(scene, plan, medium=medium, dtype=dtype, radii=radii), prepared)
    return (render, (), prepared.shading) if shading else (render, ())


def _highlight_parts(scene, plan, shading, dtype):
    """What the specular lobe of the camera pass reads, as arrays in ``dtype`` (a pytree, so that
    it can be an argument of the jitted solve): normals, view directions, the lights at the
    pixels, their radiant power, eta, the lobe's weight and the pixels' coverage."""
    params = render_params(scene, plan, dtype=dtype)
    return (jnp.asarray(shading.normal, dtype), jnp.asarray(shading.view, dtype),
            tuple(light.astype(dtype) for light in shading.lights), params.radiant, params.eta,
            jnp.asarray(shading.specular_weight, dtype), jnp.asarray(shading.coverage, dtype))


def _specular_image(parts, roughness):
    r"""The frame's surface reflection :math:`c\,L_s` (H, W, 3) [W/(mm^2 sr)] at Beckmann roughness
    ``roughness`` (differentiable in it for point and directional lights): the term
    :func:`jsss.render.shading.frame_radiance` adds, from the same :func:`specular_radiance`."""
    normal, view, lights, radiant, eta, weight, coverage = parts
    lobe = specular_radiance(normal, view, lights, radiant, eta, roughness=roughness, weight=weight)
    return coverage[..., None] * lobe


@functools.lru_cache(maxsize=16)
def _with_highlight(render):
    """``render(medium, (data, parts, held), roughness)``: the plan's frame, whose reflection
    ``held`` is at the scene's roughness, with that reflection at ``roughness`` instead (one
    function object per ``render``: the solve compiles once)."""
    return lambda medium, data, roughness: render(medium, data[0]) - data[2] + _specular_image(data[1], roughness)


# Mask a pixel where the highlight may be wrong by this share of its light or more, for a
# roughness within this factor of the scene's. The lobe kept outside the mask is as wrong as the
# guess: at 5 % its tails (m = 0.4 in the model, 0.15 in the photo, 1 % noise) still put sigma_s'
# 8.2 errors off; at 2 % every channel came within 2 errors.
HIGHLIGHT_SHARE = 0.02
ROUGHNESS_RANGE = 2.0
HIGHLIGHT_SEEN = 5  # "auto" fits the roughness where the lobe at the scene's is 2 % in this many pixels


def _highlight_doubt(parts, diffuse, roughness, spread):
    r"""(H, W): how much of each pixel's light the specular lobe may be wrong by, when the Beckmann
    roughness is known only within a factor ``spread`` of ``roughness``: the largest difference
    between the lobes at five roughnesses across that range (geometric), over the light the
    frame holds there (``diffuse`` (H, W, 3), the light besides the lobe, plus the lobe at
    ``roughness``); the largest channel. With ``spread`` 1: the lobe's own share of the light.

    A difference, not the lobe itself: the surface's Fresnel reflectance is known, and what the
    guessed roughness leaves uncertain is where the lobe's light goes (an environment's uniform
    sheen, which no roughness moves, is not masked). A lobe narrower than the stated one is
    brighter but lies inside its footprint; a wider one reaches further, so the range dilates the
    mask outwards. A diffuse level off by 2x (the start's medium, not the estimate's) moves the
    boundary of a lobe that falls as :math:`\exp(-\tan^2\theta_h/m^2)` only slightly."""
    held = np.asarray(_specular_image(parts, roughness))
    lobes = [np.asarray(_specular_image(parts, float(np.clip(m, 1e-3, 1.0))))
             for m in roughness * spread ** np.linspace(-1, 1, 5)] if spread > 1 else [np.zeros_like(held), held]
    change = np.max(lobes, axis=0) - np.min(lobes, axis=0)
    return (change / np.maximum(diffuse + held, 1e-300)).max(-1)


def fit_render(scene: Scene, photo, *, sigma=None, noise="estimate", loss: str = "huber", mask=None,
               saturation: float | None = None,
               method: str | None = None, accuracy: float = 0.001, samples: int | None = None, profile_model: str | None = None,
               g: float | None = None, init: Medium | None = None, gain=None, gain_err: float = 0.0, specular: bool = True,
               max_steps: int = 200, replans: int = 3, unconstrained: float = 0.5, dtype=jnp.float64,
               block: int = 1, rim_mm: float = 0.0, highlight: str = "auto", highlight_share: float = HIGHLIGHT_SHARE,
               roughness_range: float = ROUGHNESS_RANGE, model_error: float = MODEL_ERROR,
               progress=None) -> RenderFit:
    """Fit the scene's homogeneous material to ``photo``, a linear HDR image from the scene's camera.

    Parameters
    ----------
    scene : Scene
        Geometry, camera, lights and the material whose sigma_a and sigma_s' are fitted (its
        eta, roughness and specular weight are held; its coefficients are the starting guess
        unless ``init`` is given).
    photo : array (H, W, 3)
        Linear radiance up to the gain, at the camera's resolution.
    sigma : array broadcastable to photo, optional
        Each pixel's standard error. Default: from ``noise``.
    noise : "estimate" or float
        ``"estimate"`` (default): from the photo itself (:func:`estimate_noise`, read + shot noise
        fitted to the differences of adjacent residuals of a first fit, which is then solved again
        with it; the first fit's noise is read off the photo alone, :func:`provisional_noise`). A
        number: the relative noise of a pixel, that times the pixel's local level (the photo
        averaged over its neighbours, not the pixel's own noisy value), floored at 1 % of the
        channel's 99th percentile times it (dark pixels). A noise set too low is what
        made a path-traced photo's fit report chi2/dof 510 and errors that missed the truth.
    loss : {"huber", "squared"}
        ``"huber"`` (default): Huber's loss on the whitened residuals (quadratic within 1.345
        standard errors, linear beyond), so that heavy-tailed pixels (a path tracer's fireflies,
        a camera's hot pixels) do not steer the fit; ``"squared"``: plain least squares.
    mask, saturation, rim_mm
        See :func:`fit_pixels`.
    method : str, optional
        Render method during the fit; default: the planner's choice for ``accuracy``.
    samples : int, optional
        Image-space samples per pixel (default: the planner's); the fit's frames use one
        fixed seed, so the Monte Carlo pattern is part of the model, smooth in the medium.
    accuracy : float
        The planner's accuracy target for the fit's renders. Stricter than a display render's:
        sigma_a of a high-albedo material lives in the profile's tail, and a render profile
        0.5 % (RMS) off its exact form biased marble's sigma_a by 7 % (10 standard errors at
        320 x 240) where 0.1 % left it within its errors.
    profile_model, g : optional
        ``"dipole"`` or ``"transport"`` (and its phase function's g); default: the scene's.
    gain : float, "fit" or None
        The photo's exposure, photo value per unit linear radiance: required, since brightness is
        gain x R_d and no photo of subsurface light alone tells them apart. A number is the
        user's word (1 for a camera calibrated to radiance), or a reference's
        (:func:`gain_from_reference`, with its ``gain_err``). ``"fit"`` fits it: where the photo
        does not pin it (its relative error above :data:`GAIN_PINNED`; a specular highlight, whose
        Fresnel reflectance is known, can) the gain, R_d and sigma_a get infinite errors, the fit
        is not ``converged``, and a warning says how to add a reference. None (the default)
        raises :class:`RenderFitError` with that advice. (``True``/``False``: "fit" and 1, as
        before 2026-12-04.)
    gain_err : float
        Relative standard error of a given ``gain`` (a reference's): above 0 the gain is fitted
        with that prior, so its error reaches sigma_a and R_d; 0 holds it.
    specular : bool
        Render the surface reflection; False when the photo holds subsurface light only (then
        ``highlight`` has nothing to do: the result says ``"none"``).
    highlight : {"auto", "mask", "fit", "model"}
        What to do with the specular highlight of a photo taken through the real surface, whose
        pixels are the brightest and, under shot noise, carry the smallest errors, so that a
        highlight the model gets wrong (a roughness guessed wrong) steers sigma_a and sigma_s'.
        The result says which was done (:attr:`RenderFit.highlight`, and a line in ``history``).
        ``"fit"``: the Beckmann roughness m is one more parameter (ln m, started at the scene's;
        value and error in :attr:`RenderFit.roughness`), the lobe recomputed from the fixed
        normals, view directions and lights at every step (point and directional lights only:
        an environment's reflection is tabulated per roughness); every pixel is kept, and the
        highlight's known Fresnel reflectance still helps pin a fitted gain. It trusts the
        lobe's shape: a highlight that is not Beckmann (an extended lamp, a textured surface)
        would bias the medium through it. ``"mask"``: leave out every pixel where the lobe may be
        wrong by ``highlight_share`` or more of the pixel's light, for a roughness within a factor
        ``roughness_range`` of the scene's (the spread of five lobes across the range; the light
        besides the lobe at the start's medium), and keep the lobe at the scene's roughness
        elsewhere (an environment's uniform sheen, which no roughness moves, stays); it assumes
        nothing of the lobe's shape, but on a smooth object lit from near the camera it costs
        most of the pixels (the count is :attr:`RenderFit.highlight_pixels` and in ``history``).
        ``"model"``: the lobe at the scene's roughness, held (the behaviour before 2026-12-04).
        ``"auto"`` (default): "fit" where the highlight at the scene's roughness is
        ``highlight_share`` of the light in :data:`HIGHLIGHT_SEEN` or more fitted pixels and the
        lights are point or directional, else "mask" (which then masks nothing when there is no
        highlight, the few pixels of a glancing one, and an environment's highlight).
        Measured on a sphere photographed at m = 0.15 and fitted with the scene's m = 0.4
        (tests/fitting/test_render_highlight.py): "model" put sigma_s' up to 7 errors off
        (chi2/dof 4.4); "fit" returned m = 0.149 +- 0.0004 and the medium within 3 errors;
        "mask" left 131 of 748 pixels and the medium within 2 errors.
    highlight_share, roughness_range : float
        The mask's threshold (share of the pixel's light, default :data:`HIGHLIGHT_SHARE`) and
        the factor of the roughness's uncertainty (default :data:`ROUGHNESS_RANGE`).
    model_error : float
        The renderer's relative standard error in each channel's subsurface light (default
        :data:`MODEL_ERROR`, 1.5 %: its default frames against a path tracer), propagated into
        the errors beside the photo's noise (:func:`_model_error_covariance`): with a reference's
        gain a channel drawn 1.5 % dark is fitted about 1.5 % bright in R_d, whatever the photo's
        noise. Where the fit re-planned, the plan's own error too, as the last re-plan showed it
        (:func:`_plan_error_covariance`). 0 for a photo this renderer made itself (the errors are
        then the noise's alone).
    max_steps, replans, unconstrained
        Solver steps per round; re-plans of the variances (a round whose estimate fits worse on
        its own plan than its start did on the start's is not kept, and ``history`` says so); the
        relative standard error above which a parameter is reported as not constrained by the
        image.
    block : int
        Compare photo and render summed over ``block`` x ``block`` pixel tiles (default 1:
        per pixel). For heavy-tailed noise, such as a path tracer's fireflies, whose
        per-pixel variance estimate would let a few pixels dominate.
    progress : callable, optional
        Called with a line of text at the start of each phase (planning, the fixed passes,
        the solve).

    Returns
    -------
    RenderFit
    """
    material = scene.material
    if material.kind != "medium":
        raise RenderFitError(f"{scene.source}: fit_render fits a homogeneous medium; the scene's material is "
                             f"{material.kind} (give sigma_a, sigma_s_prime and eta, or a named material).")
    if material.maps is not None and material.maps.parametric:
        raise RenderFitError(f"{scene.source}: [material.maps] sets the coefficients per texel; fit_render fits one "
                             "homogeneous medium (remove the parameter maps; a colour map, albedo, may stay).")
    if material.normalize_profile:
        raise RenderFitError(f"{scene.source}: normalize_profile hides the medium's own reflectance, which is what "
                             "fit_render measures; remove it to fit.")
    if not scene.lights:
        raise RenderFitError(f"{scene.source}: the scene has no lights; a photo of an unlit object constrains no material.")
    estimate = isinstance(noise, str)
    if estimate and noise != "estimate":
        raise RenderFitError(f"noise must be 'estimate' or a positive relative error; got {noise!r}.")
    if not estimate and not (float(noise) > 0 and np.isfinite(float(noise))):
        raise RenderFitError(f"noise must be 'estimate' or a positive relative error; got {noise!r}.")
    if loss not in ("huber", "squared"):
        raise RenderFitError(f"loss must be 'huber' or 'squared'; got {loss!r}.")
    robust = loss == "huber"
    estimate = estimate and sigma is None
    fit_gain, held_gain, prior = _exposure(gain, gain_err)
    if highlight not in ("auto", "mask", "fit", "model"):
        raise RenderFitError(f"highlight must be 'auto', 'mask', 'fit' or 'model'; got {highlight!r}.")
    if not (0 < float(highlight_share) < 1):
        raise RenderFitError(f"highlight_share must lie in (0, 1) (0.02: the highlight is 2 % of the pixel's light); "
                             f"got {highlight_share!r}.")
    if not (np.isfinite(float(model_error)) and 0 <= float(model_error) < 1):
        raise RenderFitError(f"model_error must be a relative error in [0, 1) (0.015 for 1.5 %); got {model_error!r}.")
    if not (float(roughness_range) >= 1 and np.isfinite(float(roughness_range))):
        raise RenderFitError(f"roughness_range must be a finite factor >= 1; got {roughness_range!r}.")
    # No surface reflection in the fit: nothing to mask or fit
    highlight = highlight if specular and float(material.specular) > 0 else "none"
    photo = np.asarray(photo, float)
    use = fit_pixels(scene, photo, mask=mask, saturation=saturation, rim_mm=rim_mm)
    n_params = 6 + int(fit_gain)  # and the roughness, once the highlight's treatment is settled
    if use.sum() * 3 < 10 * n_params:
        raise RenderFitError(f"photo: only {int(use.sum())} pixels of the object can be fitted (needs at least "
                             f"{int(np.ceil(10 * n_params / 3))}); is the camera looking at the object?")
    if sigma is None:  # where it is estimated, a first, provisional noise read off the photo alone
        sigma = provisional_noise(photo, use, None if estimate else float(noise))
    sigma = np.broadcast_to(np.asarray(sigma, float), photo.shape)
    if not (np.isfinite(sigma[use]).all() and (sigma[use] > 0).all()):
        raise RenderFitError("sigma: every fitted pixel's standard error must be finite and > 0.")
    profile_model = material.profile_model if profile_model is None else profile_model
    g = material.g if g is None else float(g)
    if profile_model not in ("dipole", "transport"):
        raise RenderFitError(f"profile_model must be 'dipole' or 'transport'; got {profile_model!r}.")
    if profile_model == "transport":
        transport.check_supported(np.asarray(material.eta), g)
    eta = jnp.asarray(material.eta, dtype)
    warn_if_low_precision(eta, what="fit_render", needs="errors below the noise of a 1 %-noise photo (float64 fits)")
    start = material.medium if init is None else init
    scattering = jnp.broadcast_to(jnp.asarray(start.sigma_s_prime, dtype), (3,))
    absorption = jnp.maximum(jnp.broadcast_to(jnp.asarray(start.sigma_a, dtype), (3,)), 1e-6 * scattering)
    theta = jnp.concatenate([jnp.log(absorption),  # a start without absorption: its logarithm must be finite
                             jnp.log(scattering),
                             jnp.full(1 if fit_gain else 0, np.log(held_gain or 1.0), dtype)])
    if not (isinstance(block, int) and block >= 1):
        raise RenderFitError(f"block must be a positive integer; got {block!r}.")
    # The held gain, the reference's ln gain and its inverse relative error (_residual_fn)
    exposure = jnp.asarray([held_gain or 1.0, np.log(held_gain or 1.0), 1.0 / gain_err if prior else 0.0], dtype)
    notes, history, steps, changed = [], [], 0, []
    say = progress if progress is not None else (lambda message: None)
    def plan_for(theta, method=method):
        medium = _medium(theta, eta)
        fit_scene = dataclasses.replace(scene, material=dataclasses.replace(
            material, medium=medium, profile_model=profile_model, g=g, profile=None))  # pinned: not auto again
        plan = plan_scene(fit_scene, accuracy=accuracy, method=method, samples=samples)
        if method is None and plan.method == Method.TEXTURE_SPACE:
            # The calibration picks the cheapest knob of a frame's error; a fit needs the profile
            # itself at ``accuracy`` (a 5-Gaussian profile 7 % off biased marble's sigma_a 3x).
            plan = plan_scene(fit_scene, accuracy=accuracy, method=Method.TEXTURE_SPACE)
        if not specular:
            plan = plan.replace(Pass.SPECULAR, False, "the photo holds subsurface light only")
        return fit_scene, plan

    say(f"round 1: planning the fit's renders (accuracy {100 * accuracy:g} %)")
    fit_scene, plan = plan_for(theta)
    # Later rounds keep the start's method: an estimate that wandered to a short profile would
    # otherwise switch to a method without spread (normal filtering), which cannot see the
    # mean free path it is fitting, and the next round would lose it (measured on a marble
    # photo with the gain free: mean free path +37000 %, unconstrained).
    method_kept = plan.method
    say(f"round 1: {plan.method}: the passes that stay fixed during the fit")
    render, data, shading = _model_for(fit_scene, plan, dtype, profile_model, g, shading=True)
    roughness = float(material.roughness)
    masked = 0
    if highlight != "none":  # the plan's frame holds the highlight at the scene's roughness
        parts = _highlight_parts(fit_scene, plan, shading, dtype)
        held = _specular_image(parts, roughness)
    environment = any(isinstance(light, EnvironmentGeometry) for light in shading.lights)
    if highlight in ("auto", "mask"):
        diffuse = np.maximum(np.asarray(render(fit_scene.material.medium, data)) - np.asarray(held), 0.0)
        hidden = use & (_highlight_doubt(parts, diffuse, roughness, roughness_range) >= highlight_share)
        if highlight == "auto":  # a lobe in a pixel or two would leave the roughness to the solver
            seen = (use & (_highlight_doubt(parts, diffuse, roughness, 1.0) >= highlight_share)).sum() >= HIGHLIGHT_SEEN
            highlight = "fit" if seen and not environment else "mask"
            history.append("highlight='auto': " + (
                "the highlight is in the photo and the lights are point or directional: its roughness is fitted"
                if highlight == "fit" else "an environment's reflection is not differentiable in the roughness: "
                "its highlight is masked" if environment else "no highlight in the fitted pixels"))
    if highlight == "fit" and environment:
        raise RenderFitError(f"{scene.source}: highlight='fit' needs point and directional lights: an environment's "
                             "reflection is tabulated per roughness, not differentiable in it; use highlight='mask'.")
    fit_roughness = highlight == "fit"
    if fit_roughness:
        n_params += 1
        theta = jnp.concatenate([theta, jnp.log(jnp.full(1, roughness, dtype))])
    if highlight == "mask":
        masked, use = int(hidden.sum()), use & ~hidden
        history.append(f"highlight masked: {masked} pixels where the specular lobe may be wrong by "
                       f"{100 * highlight_share:g} % or more of the pixel's light, for a Beckmann roughness within "
                       f"{roughness_range:g}x of the scene's m = {roughness:g}; {int(use.sum())} pixels left")
        if use.sum() * 3 < 10 * n_params:
            raise RenderFitError(f"photo: only {int(use.sum())} pixels of the object are left once the highlight's "
                                 f"{masked} are masked (needs at least {int(np.ceil(10 * n_params / 3))}); fit its "
                                 "roughness instead (highlight='fit', --highlight fit)")
    elif highlight == "fit":
        history.append(f"highlight fitted: the Beckmann roughness is a parameter, starting at the scene's m = "
                       f"{roughness:g}")
    elif highlight == "model":
        history.append(f"highlight modelled at the scene's roughness m = {roughness:g} and held")
    mask = use[..., None].astype(float)
    block_used = np.asarray(_block_sums(mask, block)) > 0

    def whitening(sigma):
        block_variance = np.asarray(_block_sums(np.where(use[..., None], sigma, 0.0) ** 2, block))
        return jnp.asarray(np.where(block_used, 1.0 / np.sqrt(np.where(block_used, block_variance, 1.0)), 0.0), dtype)

    inverse_sigma = whitening(sigma)
    target = jnp.asarray(np.where(use[..., None], photo, 0.0), dtype)
    mask = jnp.asarray(mask, dtype)

    def draw(theta, model=None):
        """The fit's frame (no gain) at the parameters ``theta``, by the round's model or ``model``
        (another plan's (render, data))."""
        render_, data_ = (render, data) if model is None else model
        medium = _medium(theta, eta)
        return render_(medium, data_, jnp.exp(theta[-1])) if fit_roughness else render_(medium, data_)

    def model_of(fit_scene, plan):
        """A round's forward model (render, data): the highlight's roughness an argument where fitted."""
        render, data, shading = _model_for(fit_scene, plan, dtype, profile_model, g, shading=True)
        if not fit_roughness:
            return render, data
        parts = _highlight_parts(fit_scene, plan, shading, dtype)
        return _with_highlight(render), (data, parts, _specular_image(parts, roughness))

    if fit_roughness:  # round 1's model, its highlight held at the scene's roughness until now
        render, data = _with_highlight(render), (data, parts, held)
    plan_difference = None  # the last re-plan's change to the estimate's frame
    start_kept = False  # a round's estimate rejected for its start (below)
    for round_ in range(replans + 1):
        if fit_gain and not prior and round_ == 0:  # the best gain for the start: linear least squares
            model = np.asarray(draw(theta))
            w2 = np.asarray(inverse_sigma) ** 2
            model_b = np.asarray(_block_sums(model * np.asarray(mask), block))
            photo_b = np.asarray(_block_sums(np.asarray(target), block))
            best = (model_b * photo_b * w2).sum() / max((model_b**2 * w2).sum(), 1e-300)
            theta = theta.at[6].set(jnp.log(jnp.asarray(max(best, 1e-300), dtype)))
        say(f"round {round_ + 1}: Levenberg-Marquardt on {int(use.sum())} pixels (the first solve compiles)")
        residuals = _residual_fn(render, fit_gain, block, prior, robust, fit_roughness)
        args = (data, target, mask, inverse_sigma, eta, exposure)
        start = theta  # on its own plan: the round's plan was made for it
        theta, n_steps, solved, jac = _solve(residuals, theta, args, max_steps=max_steps,
                                             rtol=1e-8, atol=1e-10)
        steps += int(n_steps)
        if replans == 0:  # the caller holds the start's plan
            break
        # The plan was made for the start: made again for the estimate, is it the same? The
        # passes it turns on (a translucent shadow map, single scattering) and the variances
        # must be the estimate's own: on variances planned for another medium the truth fits
        # worse than a biased estimate (marble from 3x off: chi^2/dof 1.18 at the truth,
        # 0.99 at a sigma_a 18 % low, so the fit stopped there).
        say(f"round {round_ + 1}: checking the plan against the estimate")
        next_scene, next_plan = plan_for(theta, method_kept)
        changed = _plan_changes(plan, next_plan, fit_scene, next_scene, data)
        if not changed:
            break
        say(f"round {round_ + 1}: the estimate's own plan moves ({', '.join(changed)}): its fixed passes")
        next_render, next_data = model_of(next_scene, next_plan)
        next_args = (next_data, *args[1:])
        next_residuals = _residual_fn(next_render, fit_gain, block, prior, robust, fit_roughness)
        plan_difference = np.asarray(draw(theta, (next_render, next_data))) - np.asarray(draw(theta))
        # The objective is each estimate's misfit on its own plan, which jumps where the plan
        # does. A round whose estimate is worse there than its start was on the start's own
        # plan moved along the plan's error, not the photo's: ketchup's red mean free path went
        # 4.1 -> 8.5 -> 12 -> 13.8 mm while this misfit went 385317 -> 339895 -> 341505 -> 374322.
        cost, start_cost = float(_cost(next_residuals, theta, next_args)), float(_cost(residuals, start, args))
        if cost > start_cost:
            history.append(f"round {round_ + 1}'s estimate not kept: on its own plan ({', '.join(changed)}) its "
                           f"misfit is {cost:.7g}, above its start's {start_cost:.7g} on the start's plan; the start is "
                           "the estimate, on its own plan, and the re-plan's change is in the errors")
            say(history[-1])
            theta, changed, start_kept = start, [], True
            break
        if round_ == replans:  # the plan moves still, and no round is left: the estimate is not its own plan's
            notes.append(f"the plan did not settle: re-planned {replans} times for the estimate, and the last "
                         f"estimate moves it again ({', '.join(changed)}); the estimate and its errors hold for "
                         "a plan made for another medium (replans=... for more rounds)")
            break
        history.append(f"re-planned for the estimate after round {round_ + 1}: " + ", ".join(changed))
        say(history[-1])
        fit_scene, plan, render, data = next_scene, next_plan, next_render, next_data
    if fit_roughness:
        parts = data[1]
    if estimate:  # the noise from the first fit's residuals, then the fit again with it
        gain_now = float(np.exp(theta[6])) if fit_gain else held_gain
        expected = gain_now * np.asarray(draw(theta))
        sigma = estimate_noise(photo - expected, expected, use)
        inverse_sigma = whitening(sigma)
        args = (data, target, mask, inverse_sigma, eta, exposure)
        if not start_kept:  # (solved again, a kept start would move to the estimate not kept)
            say("the photo's noise estimated from the first fit's residuals: solving again with it")
            theta, n_steps, solved, jac = _solve(residuals, theta, args, max_steps=max_steps, rtol=1e-8, atol=1e-10)
            steps += int(n_steps)
        level = np.median(expected[use], axis=0)
        history.append("noise estimated from the photo (adjacent residuals): "
                       + ", ".join(f"{c} {100 * s / max(v, 1e-300):.2g} %" for c, s, v in
                                   zip("RGB", np.median(sigma[use], axis=0), level)) + " of the median pixel"
                       + ("; the kept start not solved again with it" if start_kept else ""))
    if start_kept:
        jac = _jacobian(residuals, theta, args)
    if model_error > 0:
        history.append(f"the errors include the renderer's own, {100 * float(model_error):g} % of each channel's "
                       "subsurface light (model_error), beside the photo's noise")
    r = np.asarray(residuals(theta, args))
    m = int(block_used.sum()) * 3 + int(prior)  # used tiles times channels, and the reference's gain
    chi2 = reduced_chi2(r @ r, m, n_params)
    if robust:  # chi^2 from the median square (0.4549 for a unit Gaussian): 1 % of fireflies 3000
        # errors off had made it 65 and every error 8x too wide, though the estimate was right
        plain = np.asarray(_residual_fn(render, fit_gain, block, prior, False, fit_roughness)(theta, args))
        tiles = block_used.shape[:2] + (3,)
        plain = plain[:int(np.prod(tiles))][np.broadcast_to(block_used, tiles).reshape(-1)]  # the fitted tiles
        chi2 = float(np.median(plain**2) / 0.45494) * m / max(m - n_params, 1)
        outliers = float(np.mean(np.abs(plain) > 5))
        if outliers > 0.001:
            notes.append(f"{100 * outliers:.2g} % of the fitted pixels lie beyond 5 standard errors (fireflies, hot "
                         "pixels, or a part of the scene the model lacks); Huber's loss kept them from steering the fit")
    J = np.asarray(jac)
    if not (np.isfinite(r).all() and np.isfinite(J).all()):
        # A NaN from the renderer would otherwise surface as "eigenvalues did not converge".
        held = np.exp(np.asarray(_held_in_range(theta)))
        raise RenderFitError(f"{scene.source}: the fit's render or its derivative is not finite at sigma_a = "
                             f"{held[:3].tolist()}, sigma_s' = {held[3:6].tolist()} "
                             f"({plan.method}, {profile_model}); "
                             "this is a bug in jsss: please report it with the scene.")
    cov, null = covariance(J, error_scale(chi2))
    image = draw(theta)
    if model_error > 0:  # the renderer's own error: a share of the light no photo's noise shows
        specular_part = (_specular_image(parts, jnp.exp(theta[-1])) if fit_roughness
                         else held if highlight in ("mask", "model") else jnp.zeros_like(image))
        slopes = _model_error_slopes(theta, args, image, specular_part, fit_gain, block, robust, prior)
        cov = cov + _model_error_covariance(J, slopes, float(model_error))
        if plan_difference is not None:  # and the plan's, where the last re-plan showed it
            cov = cov + _plan_error_covariance(J, theta, args, image, plan_difference, fit_gain, block, robust, prior)
            drawn = np.asarray(image)
            seen = use[..., None] & (drawn > 0)
            change = float(np.sqrt(np.mean((plan_difference[seen] / drawn[seen]) ** 2)))
            history.append(f"the errors include the plan's own: the last re-plan moved the estimate's frame by "
                           f"{100 * change:.2g} % RMS per pixel")
    image = np.asarray(image)
    theta_np = np.asarray(theta)
    rel = standard_errors(np.eye(len(theta_np)), cov, null)  # errors of logarithms = relative errors
    A = np.asarray(jax.jacfwd(_artist)(theta[:6], profile_model, g, eta))
    artist = np.asarray(_artist(theta[:6], profile_model, g, eta))
    artist_err = standard_errors(np.pad(A, ((0, 0), (0, len(theta_np) - 6))), cov, null)
    held = np.asarray(_held_in_range(theta))
    outside = np.abs(held - theta_np[:6]) > 1e-9 * np.maximum(1.0, np.abs(theta_np[:6]))
    rel[:6] = np.where(outside, np.inf, rel[:6])  # held at the edge: the photo did not put it there
    channel_held = np.tile(outside[:3] | outside[3:6], 2)  # R_d and mean free path of that channel
    artist_err = np.where(channel_held, np.inf, artist_err)
    sigma_a, sigma_s = np.exp(held[:3]), np.exp(held[3:6])
    names = ([f"ln sigma_a {c}" for c in "RGB"] + [f"ln sigma_s' {c}" for c in "RGB"] + (["ln gain"] if fit_gain else [])
             + (["ln roughness"] if fit_roughness else []))
    loose = [f"{name[3:]} ({'inf' if not np.isfinite(e) else f'{100 * e:.0f} %'})"
             for name, e in zip(names, rel) if not e <= unconstrained]
    if loose:
        notes.append("not constrained by the image (relative standard error): " + ", ".join(loose)
                     + "; their values are the solver's, not the photo's (a uniformly lit object hides the mean "
                       "free path; Lambert has no spread at all)")
    if outside.any():
        notes.append("ran out of the model's range (sigma_s' " + "-".join(f"{v:g}" for v in SCATTERING_RANGE)
                     + " /mm, sigma_a / sigma_s' up to " + f"{ABSORPTION_RATIO_RANGE[1]:g}) in "
                     + ", ".join(n[3:] for n, o in zip(names, outside) if o)
                     + ": held at its edge, not a measurement (the photo does not constrain it)")
    albedo = sigma_s / (sigma_a + sigma_s)
    start_albedo = np.asarray(scattering) / np.asarray(absorption + scattering)
    edge = [c for c, a, a0 in zip("RGB", albedo, start_albedo) if a > 0.9999 and a0 <= 0.9999]
    if edge:
        notes.append("ran to the edge of the parameters: no absorption left in " + "/".join(edge)
                     + (" (with the gain fitted, brightness is gain x R_d and the fit traded one for the other; "
                        "hold the gain for a calibrated camera: gain=1, --no-gain)" if fit_gain and not prior else ""))
    if chi2 > 4:
        notes.append(f"poor fit: chi2/dof {chi2:.1f} (expected about 1); the errors are widened by its square root. "
                     "Likely a wrong eta, geometry or light, a noise level set too low, or the profile model's bias")
    final = Medium(jnp.asarray(sigma_a), jnp.asarray(sigma_s), material.eta)
    if fit_roughness:  # roughness (the scene's) stays what the frames hold, until here
        roughness, roughness_err = float(np.exp(theta_np[-1])), float(np.exp(theta_np[-1]) * rel[-1])
    else:
        roughness_err = 0.0
    gain_value = float(np.exp(theta_np[6])) if fit_gain else held_gain
    sigma_a_err, gain_rel = sigma_a * rel[:3], float(rel[6]) if fit_gain else 0.0
    unresolved = fit_gain and not prior and not gain_rel <= GAIN_PINNED
    if unresolved:  # one direction, gain x R_d: no finite error along it (GAIN_PINNED)
        notes.insert(0, f"exposure unresolved: the photo's brightness is gain x R_d and nothing in it separates them "
                        f"(the fitted gain's relative error is {100 * gain_rel:.0f} %, above {100 * GAIN_PINNED:g} %); "
                        "R_d, sigma_a and the gain have no finite error: photograph a white target of known "
                        "reflectance (--reference-scene/--reference-photo) or give the camera's gain (--gain)")
        gain_rel, sigma_a_err = np.inf, np.full(3, np.inf)
        artist_err = np.concatenate([np.full(3, np.inf), artist_err[3:]])
    return RenderFit(final, sigma_a_err, sigma_s * rel[3:6], gain_value,
                     gain_value * gain_rel, artist[:3], artist_err[:3], artist[3:],
                     artist_err[3:], cov, tuple(names), chi2, steps,
                     bool(solved) and not edge and not unresolved and not (replans and changed)
                     and bool(np.all(np.isfinite(theta_np)))
                     and bool(np.all(np.isfinite(rel))),
                     int(use.sum()), plan.method, profile_model,
                     image * gain_value, use, tuple(notes), tuple(history), np.asarray(sigma), unresolved,
                     highlight, masked, roughness, roughness_err, float(model_error))
