r"""A brute-force reference: the exact profile integrated over the whole surface.

For each visible pixel's surface point :math:`x`,

.. math:: M(x) = \int_S R(|x - y|)\,E(y)\,dA_y
          \approx E(x)\int_0^{r_c} R(r)\,2\pi r\,dr
          + \frac{A}{N}\sum_{|x - y_j| \ge r_c} R(|x - y_j|)\,E(y_j),

with :math:`N` points :math:`y_j` spread uniformly by area over every triangle (seen or
not), :math:`E(y_j)` from the same shadow maps as the renderer, and :math:`R` the *exact*
profile (dipole, multilayer stack or the given Gaussians; not a fit). The disc of radius
:math:`r_c` (three sample spacings) around :math:`x` is integrated in its tangent plane
with :math:`E(x)`: the profile's sharp core is far narrower than the spacing of any
affordable sample set. Unlike the renderer's methods this sees the whole surface, so it
includes light from parts the camera does not see. Cost: pixels x samples profile
evaluations -- a reference, not a renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from numpy import trapezoid

from .environment import EnvironmentGeometry, environment_irradiance
from .image_space import camera_buffers
from .lighting import irradiance, light_geometry, shadow_map
from .profiles import exact_profile
from .scene import Scene
from .shading import diffuse_radiance

__all__ = ["ReferenceFrame", "reference_radiance", "surface_samples", "white_lambertian_radiance"]


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
    """Diffuse radiance (H, W, 3) and its own Monte Carlo error (relative RMS, from two halves)."""

    radiance: np.ndarray
    mask: np.ndarray
    noise: float
    samples: int
    near_radius: float


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


def reference_radiance(scene: Scene, *, samples: int = 200_000, seed: int = 0, chunk: int = 128,
                       oblique: bool | None = None) -> ReferenceFrame:
    """The diffuse radiance of ``scene`` by brute-force surface integration (float64 if enabled).

    ``oblique``: scale the irradiance by the oblique-incidence law (:mod:`jsss.diffusion.incidence`);
    default: where the planner would at the scene's accuracy, so that a frame is compared
    with the same physics it was planned to simulate.
    """
    from .planner import deposit_depth_decision, oblique_incidence_decision

    mesh, material = scene.mesh, scene.material
    if oblique is None:
        oblique = oblique_incidence_decision(material, scene.accuracy)[0]
    oblique_medium = material.medium if oblique and material.medium is not None else None
    deposit_medium = material.medium if material.medium is not None and deposit_depth_decision(
        scene, scene.accuracy)[0] else None
    buffers = camera_buffers(mesh, scene.camera)
    maps = [shadow_map(mesh, light, size=scene.shadow_map_size) for light in scene.lights]
    radiant = jnp.asarray(np.array([np.asarray(l.color) * l.intensity for l in scene.lights]), float)
    eta = jnp.broadcast_to(jnp.asarray(material.eta, float), (3,))
    pixel_lights = [light_geometry(buffers.position, buffers.normal, buffers.mask, light, m)
                    for light, m in zip(scene.lights, maps)]
    E_pixel = np.asarray(irradiance(pixel_lights, radiant, eta, medium=oblique_medium, deposit=deposit_medium))
    position, normal, area = surface_samples(mesh, samples, seed=seed)
    sample_lights = [light_geometry(position, normal, np.ones(len(position), bool), light, m)
                     for light, m in zip(scene.lights, maps)]
    E_samples = np.asarray(irradiance(sample_lights, radiant, eta, medium=oblique_medium, deposit=deposit_medium))
    lo, hi = mesh.bounds
    r, table = _tabulated_profile(material, 2 * float(np.linalg.norm(hi - lo)))
    near = 3 * np.sqrt(area / samples)
    inside = r <= near
    core = trapezoid(table[inside] * 2 * np.pi * r[inside, None], r[inside], axis=0)  # (3,)
    log_r, log_table = jnp.log(jnp.asarray(r[1:])), jnp.log(jnp.asarray(table[1:]))

    def profile(d):
        ld = jnp.log(jnp.maximum(d, r[1]))[..., None]
        return jnp.exp(jax.vmap(lambda t: jnp.interp(ld[..., 0], log_r, t), in_axes=1, out_axes=-1)(log_table))

    ys, Es = jnp.asarray(position), jnp.asarray(E_samples)
    half = (samples + 1) // 2  # even-index points

    @jax.jit
    def far_field(xs):
        d = jnp.sqrt(jnp.sum((xs[:, None, :] - ys[None]) ** 2, -1))  # (P, N)
        contribution = jnp.where((d >= near)[..., None], profile(d) * Es[None], 0.0)
        return contribution[:, 0::2].sum(1), contribution[:, 1::2].sum(1)

    visible = np.flatnonzero(buffers.mask.ravel())
    points = buffers.position.reshape(-1, 3)[visible]
    first, second = [], []
    for start in range(0, len(points), chunk):
        a, b = far_field(jnp.asarray(points[start:start + chunk]))
        first.append(np.asarray(a))
        second.append(np.asarray(b))
    first, second = np.concatenate(first), np.concatenate(second)
    E_visible = E_pixel.reshape(-1, 3)[visible]
    M_halves = [E_visible * core + area / half * first, E_visible * core + area / (samples - half) * second]
    M = 0.5 * (M_halves[0] + M_halves[1])
    noise = float(np.sqrt(np.mean((M_halves[0] - M_halves[1]) ** 2)) / 2 / np.sqrt(np.mean(M**2)))
    exitance = np.zeros((buffers.mask.size, 3))
    exitance[visible] = M
    exitance = exitance.reshape(buffers.mask.shape + (3,))
    cos_view = (buffers.normal * buffers.view).sum(-1)
    L = np.asarray(diffuse_radiance(jnp.asarray(exitance), jnp.asarray(cos_view), eta)) * buffers.coverage[..., None]
    return ReferenceFrame(L, buffers.mask, noise, samples, float(near))
