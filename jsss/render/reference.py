r"""A brute-force reference: the exact profile integrated over the whole surface.

For each visible pixel's surface point :math:`x`,

.. math:: M(x) = \int_S R(|x - y|)\,E(y)\,dA_y
          \approx E(x)\int_0^{r_c} R(r)\,2\pi r\,dr
          + \frac{A}{N}\sum_{|x - y_j| \ge r_c} R(|x - y_j|)\,E(y_j),

with :math:`N` points :math:`y_j` spread uniformly by area over every triangle (seen or
not), :math:`E(y_j)` from the same shadow maps as the renderer, and :math:`R` the *exact*
profile (dipole, multilayer stack or the given Gaussians; not a fit; with
``profile_model="transport"`` a homogeneous medium's transport profile wherever the tables
cover it, whatever model the frame renders with). The disc of radius
:math:`r_c` (three sample spacings) around :math:`x` is integrated in its tangent plane
with :math:`E(x)`: the profile's sharp core is far narrower than the spacing of any
affordable sample set. Unlike the renderer's methods this sees the whole surface, so it
includes light from parts the camera does not see. Cost: pixels x samples profile
evaluations -- a reference, not a renderer.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from numpy import trapezoid

from ..diffusion.exit_law import exit_law
from ..numerics import interpolate_rows
from .environment import EnvironmentGeometry, environment_irradiance
from .first_leg import FIRST_LEG_QUANTILE_COUNT, first_leg_moves, first_leg_quantiles
from .image_space import camera_buffers
from .last_leg import away_from_eye, last_leg_steps
from .lighting import irradiance, light_geometry, shadow_map
from .profiles import exact_profile
from .scene import Scene
from .shading import angular_exit_lobe, diffuse_radiance

__all__ = ["ReferenceFrame", "reference_radiance", "surface_samples", "truth_material", "white_lambertian_radiance"]


def white_lambertian_radiance(scene: Scene) -> np.ndarray:
    r"""What the camera sees of a white Lambertian object of the scene's shape: :math:`E / \pi`.

    (H, W, 3) radiance, with the scene's lights and shadows, zero off the object. The upper
    bound of any material's diffuse light (energy conservation), and the exposure that shows
    a render at its true brightness; ``benchmarks/transport_truth.py`` checks it against
    Mitsuba to prove both renderers light and see the scene alike.
    """
    buffers = camera_buffers(scene.mesh, scene.camera)
    radiance = 0.0
    for light in scene.lights:
        g = light_geometry(buffers.position, buffers.normal, buffers.mask, light,
                           shadow_map(scene.mesh, light, size=scene.shadow_map_size))
        if isinstance(g, EnvironmentGeometry):  # eta = 1: no Fresnel, the kernel is the bare cosine
            colour = jnp.asarray(np.asarray(light.color) * light.intensity, float)
            radiance = radiance + np.asarray(environment_irradiance(g.astype(float), colour, jnp.ones(3)))
            continue
        arriving = np.clip(np.asarray(g.cosine), 0, None) * np.asarray(g.falloff) * np.asarray(g.visible)
        radiance = radiance + arriving[..., None] * np.asarray(light.color) * light.intensity
    return np.asarray(radiance / np.pi * np.asarray(buffers.coverage)[..., None], dtype=float)


@dataclass(frozen=True, eq=False)
class ReferenceFrame:
    """Diffuse radiance (H, W, 3) and its own Monte Carlo error (relative RMS, from two halves);
    ``profile``: what was integrated (``"dipole"``, ``"transport"``, ``"layers"``, ``"gaussians"``);
    ``exit_angle``: whether the exitance left by Chandrasekhar's exit law (else the flat lobe);
    ``last_leg``: whether each channel was integrated around the point its light was last
    scattered under (:mod:`jsss.render.last_leg`); ``first_leg``: and moved back toward the
    light by its first leg (:mod:`jsss.render.first_leg`)."""

    radiance: np.ndarray
    mask: np.ndarray
    noise: float
    samples: int
    near_radius: float
    profile: str = ""
    exit_angle: bool = False
    last_leg: bool = False
    first_leg: bool = False


def surface_samples(mesh, count: int, *, seed: int = 0):
    """``count`` points spread evenly by area on ``mesh``: positions (N, 3), unit normals (N, 3), total area.

    Stratified (quasi-Monte Carlo): the i-th point falls in the triangle holding the area
    fraction (i + s)/N, at barycentrics from a 2-D Kronecker sequence, so every triangle
    receives its share of points to within one and they do not clump. Points with even and
    odd index form two interleaved halves of the same quality.
    """
    v, f = mesh.vertices, mesh.faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    shift = np.random.default_rng(seed).random(3)
    cumulative = np.cumsum(area) / area.sum()
    face = np.minimum(np.searchsorted(cumulative, (np.arange(count) + shift[0]) / count), len(f) - 1)
    golden = 1.32471795724474602596  # plastic number: the 2-D Kronecker (R2) sequence
    a = np.mod(shift[1] + np.arange(count) / golden, 1.0)
    b = np.mod(shift[2] + np.arange(count) / golden**2, 1.0)
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    bary = np.stack([1 - a - b, a, b], 1)
    tri = f[face]
    position = np.einsum("nk,nkd->nd", bary, v[tri])
    normal = np.einsum("nk,nkd->nd", bary, mesh.normals[tri])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return position, normal, float(area.sum())


def _tabulated_profile(material, r_max):
    r = np.concatenate([[0.0], np.geomspace(1e-5, r_max, 3000)])
    values = np.maximum(np.asarray(exact_profile(material, r)), 1e-300)  # (n, 3)
    return r, values


def truth_material(material, profile_model: str | None = "transport"):
    """``material`` with its homogeneous medium's profile pinned to ``profile_model`` where it applies.

    ``"transport"`` applies where :mod:`jsss.transport`'s tables cover the medium (its eta,
    ``g``, albedo); a stack, a Gaussian sum, a medium the tables do not cover, or ``None``
    keep the material's own profile. Returns (material, the profile it integrates).
    """
    if material.layers:
        return material, "layers"
    if material.gaussians is not None or material.medium is None:
        return material, "gaussians"
    if profile_model is None or profile_model == material.profile_model:
        return material, material.profile_model
    if profile_model == "transport":
        from .. import transport

        try:
            transport.check_medium(material.medium, g=material.g)
        except ValueError:
            return material, material.profile_model
    return dataclasses.replace(material, profile_model=profile_model, profile=None), profile_model


def reference_radiance(scene: Scene, *, samples: int = 200_000, seed: int = 0, chunk: int = 128,
                       oblique: bool | None = None, profile_model: str | None = None,
                       exit_angle: bool | None = None, last_leg: bool | None = None,
                       first_leg: bool | None = None) -> ReferenceFrame:
    """The diffuse radiance of ``scene`` by brute-force surface integration (float64 if enabled).

    ``oblique``: scale the irradiance by the oblique-incidence law (:mod:`jsss.diffusion.incidence`);
    default: where the planner would at the scene's accuracy, so that a frame is compared
    with the same physics it was planned to simulate (the deposit-depth pass likewise).
    ``exit_angle``: spread the exitance by Chandrasekhar's exit law of every order
    (:mod:`jsss.diffusion.exit_law`) instead of the flat diffusion lobe; default: where the planner
    would.
    ``last_leg``: integrate each channel around the point its light toward the camera was last
    scattered under, the mean step of :mod:`jsss.render.last_leg` away from the eye; default:
    where the physics calls for it (:func:`jsss.render.planner.last_leg_decision`, whatever method).
    ``first_leg``: move that point back toward each light by its first leg's mean step
    (:mod:`jsss.render.first_leg`); default: where the physics calls for it
    (:func:`jsss.render.planner.first_leg_decision`). A moved point off the surface (past an
    open rim) gathers the light that diffuses out to it, its own irradiance none.
    ``profile_model``: ``None`` integrates the material's own profile; ``"transport"`` the
    transport tables' wherever they cover the medium (:func:`truth_material`), the truth the
    planner's calibration measures every method against, the frame's Gaussian fit of its own
    model included.
    """
    from .planner import (
        deposit_depth_decision,
        exit_angle_decision,
        first_leg_decision,
        last_leg_decision,
        oblique_incidence_decision,
    )

    mesh, material = scene.mesh, scene.material
    if oblique is None:
        oblique = oblique_incidence_decision(material, scene.accuracy)[0]
    if exit_angle is None:
        exit_angle = exit_angle_decision(material, scene.accuracy, first_bounce_apart=False)[0]
    exit_angle = exit_angle and material.medium is not None
    if last_leg is None:
        last_leg = last_leg_decision(scene, scene.accuracy)[0]
    last_leg = last_leg and material.medium is not None
    if first_leg is None:
        first_leg = first_leg_decision(scene, scene.accuracy)[0]
    first_leg = first_leg and material.medium is not None
    moved_points = last_leg or first_leg
    oblique_medium = material.medium if oblique and material.medium is not None else None
    deposit_medium = material.medium if material.medium is not None and deposit_depth_decision(
        scene, scene.accuracy)[0] else None
    buffers = camera_buffers(mesh, scene.camera)
    maps = [shadow_map(mesh, light, size=scene.shadow_map_size) for light in scene.lights]
    radiant = jnp.asarray(np.array([np.asarray(l.color) * l.intensity for l in scene.lights]), float)
    eta = jnp.broadcast_to(jnp.asarray(material.eta, float), (3,))
    pixel_lights = [light_geometry(buffers.position, buffers.normal, buffers.mask, light, m)
                    for light, m in zip(scene.lights, maps)]
    E_pixel = np.array(irradiance(pixel_lights, radiant, eta, medium=oblique_medium, deposit=deposit_medium))
    centres = np.broadcast_to(buffers.position[..., None, :], buffers.position.shape[:-1] + (3, 3))  # per channel
    medium = jax.tree_util.tree_map(jnp.asarray, material.medium) if moved_points else None
    if last_leg:  # each channel's point moved along the tangent plane, away from the eye
        steps = np.asarray(last_leg_steps(medium, buffers.normal, buffers.view, pixel_lights, radiant, radiant.dtype,
                                          first_bounce_apart=False))            # (H, W, 3) mm
        centres = centres + steps[..., None] * away_from_eye(buffers.normal, buffers.view)[..., None, :]
    # and back toward the light, where the light it gathers was deposited from: the first leg's
    # spread as its texture-space pass takes it, each quantile's point integrated over its own
    # share of the samples (the cost of one point)
    first_moves = np.asarray(first_leg_moves(medium, buffers.normal, buffers.view, pixel_lights, radiant, eta,
                                             radiant.dtype)) if first_leg else 0.0   # (H, W, 3, 3) mm
    quantiles = first_leg_quantiles(FIRST_LEG_QUANTILE_COUNT) if first_leg else np.zeros(1)
    position, normal, area = surface_samples(mesh, samples, seed=seed)
    near = 3 * np.sqrt(area / samples)
    if moved_points:
        from scipy.spatial import cKDTree

        surface = cKDTree(position)
    sample_lights = [light_geometry(position, normal, np.ones(len(position), bool), light, m)
                     for light, m in zip(scene.lights, maps)]
    E_samples = np.asarray(irradiance(sample_lights, radiant, eta, medium=oblique_medium, deposit=deposit_medium))
    lo, hi = mesh.bounds
    integrated, profile_name = truth_material(material, profile_model)
    r, table = _tabulated_profile(integrated, 2 * float(np.linalg.norm(hi - lo)))
    inside = r <= near
    core = trapezoid(table[inside] * 2 * np.pi * r[inside, None], r[inside], axis=0)  # (3,)
    log_table = jnp.log(jnp.asarray(table[1:]))
    n, log_first, log_step = len(r) - 1, float(np.log(r[1])), float(np.log(r[-1] / r[1]) / (len(r) - 2))

    def profile(d):
        # Linear in log R over log r, as jnp.interp would, but the radii are evenly spaced in
        # log r, so the interval is found by arithmetic instead of a search: 1.8x faster.
        x = jnp.clip((jnp.log(jnp.maximum(d, r[1])) - log_first) / log_step, 0.0, n - 1.0)
        return jnp.exp(interpolate_rows(x, log_table))

    @jax.jit
    def far_field(xs, ys, Es):
        d = jnp.sqrt(jnp.sum((xs[:, None, :] - ys[None]) ** 2, -1))  # (P, N)
        contribution = jnp.where((d >= near)[..., None], profile(d) * Es[None], 0.0)
        return contribution[:, 0::2].sum(1), contribution[:, 1::2].sum(1)

    @jax.jit
    def far_field_per_channel(xs, ys, Es):  # xs (P, C, 3): each channel about its own point
        d = jnp.sqrt(jnp.sum((xs[:, None, :, :] - ys[None, :, None]) ** 2, -1))  # (P, N, C)
        x = jnp.clip((jnp.log(jnp.maximum(d, r[1])) - log_first) / log_step, 0.0, n - 1.0)
        low = jnp.minimum(jnp.floor(x).astype(jnp.int32), n - 2)
        t, channel = x - low, jnp.arange(d.shape[-1])
        values = jnp.exp((1 - t) * log_table[low, channel] + t * log_table[low + 1, channel])
        contribution = jnp.where(d >= near, values * Es[None], 0.0)
        return contribution[:, 0::2].sum(1), contribution[:, 1::2].sum(1)

    visible = np.flatnonzero(buffers.mask.ravel())
    integrate = far_field_per_channel if moved_points else far_field
    M_halves = [0.0, 0.0]
    for k, q in enumerate(quantiles):
        moved_centres = centres - q * first_moves
        E_k = E_pixel.copy()
        if moved_points:  # each channel lit at its point, none where that is off the surface
            for c in range(3):
                moved = [light_geometry(moved_centres[..., c, :], buffers.normal, buffers.mask, light, m)
                         for light, m in zip(scene.lights, maps)]
                E_k[..., c] = np.asarray(irradiance(moved, radiant, eta, medium=oblique_medium,
                                                    deposit=deposit_medium))[..., c]
            gap, _ = surface.query(moved_centres.reshape(-1, 3))
            E_k = np.where(gap.reshape(E_k.shape) > near, 0.0, E_k)
        points = (moved_centres.reshape(-1, 3, 3) if moved_points else buffers.position.reshape(-1, 3))[visible]
        ys, Es = jnp.asarray(position[k::len(quantiles)]), jnp.asarray(E_samples[k::len(quantiles)])
        half = (len(ys) + 1) // 2  # even-index points
        first, second = [], []
        for start in range(0, len(points), chunk):
            a, b = integrate(jnp.asarray(points[start:start + chunk]), ys, Es)
            first.append(np.asarray(a))
            second.append(np.asarray(b))
        first, second = np.concatenate(first), np.concatenate(second)
        E_visible = E_k.reshape(-1, 3)[visible]
        M_halves[0] = M_halves[0] + (E_visible * core + area / half * first) / len(quantiles)
        M_halves[1] = M_halves[1] + (E_visible * core + area / (len(ys) - half) * second) / len(quantiles)
    M = 0.5 * (M_halves[0] + M_halves[1])
    noise = float(np.sqrt(np.mean((M_halves[0] - M_halves[1]) ** 2)) / 2 / np.sqrt(np.mean(M**2)))
    exitance = np.zeros((buffers.mask.size, 3))
    exitance[visible] = M
    exitance = exitance.reshape(buffers.mask.shape + (3,))
    cos_view = (buffers.normal * buffers.view).sum(-1)
    if exit_angle:  # no single scattering apart here: the lobe of every order
        law = exit_law(jax.tree_util.tree_map(jnp.asarray, material.medium), first_bounce_apart=False)
        lobe = angular_exit_lobe(law, jnp.asarray(cos_view), [g.astype(radiant.dtype) for g in pixel_lights],
                                 radiant, eta)
        L = exitance * np.asarray(lobe) * buffers.coverage[..., None]
    else:
        L = np.asarray(diffuse_radiance(jnp.asarray(exitance), jnp.asarray(cos_view), eta)) * buffers.coverage[..., None]
    return ReferenceFrame(L, buffers.mask, noise, samples, float(near), profile_name, bool(exit_angle),
                          bool(last_leg), bool(first_leg))
