r"""Lights, shadow maps and translucent shadow maps (d'Eon 2007 sec. 5.4).

Geometry first (NumPy, once per mesh and light): a depth map seen from the light marks
which points are shadowed and, for a shadowed point, how far light travelled through the
object to reach it and where it entered (the *front* point's UV). Then the JAX passes:

* :func:`irradiance` -- light transmitted into the surface per texel or pixel,
  :math:`E = \sum_l I_l\,c_l\,\cos\theta_l\,F_t(\cos\theta_l, \eta)\,V_l / d_l^{p}`
  (``p = 2`` for point lights, 0 for directional ones).
* :func:`translucent_transmission` -- light leaving a shadowed point that entered at the
  front point a distance ``d`` away. A Gaussian of the profile evaluated at the 3-D
  distance :math:`\sqrt{r^2 + d^2}` factorises,

  .. math:: G(v, \sqrt{r^2 + d^2}) = \frac{e^{-(r^2 + d^2)/2v}}{2\pi v}
            = e^{-d^2/2v}\,G(v, r),

  so the exitance is :math:`\sum_i w_i\,e^{-d^2/2v_i}\,(G_i * E)(x_{front})`: each blurred
  irradiance texture read at the front point, attenuated by :math:`e^{-d^2/2v_i}` (d'Eon
  prints :math:`e^{-d^2/v_i}`; with his :math:`G(v, r) = e^{-r^2/2v}/2\pi v` the 2 belongs).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..diffusion.incidence import deposit_depth, incidence_law
from ..fresnel import fresnel_transmittance
from .environment import (
    VISIBILITY_DIRECTIONS,
    VISIBILITY_MAP_SIZE,
    EnvironmentGeometry,
    environment_geometry,
    environment_irradiance,
    environment_shadows,
    fibonacci_directions,
)
from .mesh import Mesh, shadows_itself
from .raster import OrthographicView, PerspectiveView, rasterize, surface_attributes

__all__ = ["Light", "LightGeometry", "ShadowMap", "irradiance", "light_geometry", "node_irradiance", "shadow_map",
           "translucent_transmission"]


@dataclass(frozen=True)
class Light:
    """A point or directional light.

    Attributes
    ----------
    kind : {"point", "directional"}
    color : (3,) linear RGB, multiplies ``intensity``
    intensity : float
        Radiant intensity [W/sr] of a point light, or irradiance at normal incidence [W/mm^2]
        of a directional one (any consistent unit: images are linear in it).
    position : (3,) [mm], point lights
    direction : (3,), directional lights: the direction the light *travels*
    """

    kind: str
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    position: tuple | None = None
    direction: tuple | None = None

    def __post_init__(self):
        if self.kind not in ("point", "directional"):
            raise ValueError(f"light kind must be 'point' or 'directional'; got {self.kind!r}.")
        if self.kind == "point" and self.position is None:
            raise ValueError("a point light needs a position.")
        if self.kind == "directional":
            d = np.asarray(self.direction if self.direction is not None else (0, 0, 0), float)
            if d.shape != (3,) or np.linalg.norm(d) == 0:
                raise ValueError(f"a directional light needs a non-zero 3-vector direction; got {self.direction}.")
        if np.any(np.asarray(self.color) < 0) or self.intensity < 0:
            raise ValueError(f"light color and intensity must be non-negative; got {self.color}, {self.intensity}.")


@dataclass(frozen=True, eq=False)
class ShadowMap:
    """Depth and front-surface UV as seen from a light."""

    view: OrthographicView | PerspectiveView
    depth: np.ndarray
    front_uv: np.ndarray
    mask: np.ndarray


def shadow_map(mesh: Mesh, light: Light, *, size: int = 512) -> ShadowMap:
    """Rasterize ``mesh`` from ``light``: an orthographic map for directional lights, a perspective one for points.

    For an :class:`~jsss.render.environment.Environment`, its tables and (where the mesh can
    shadow itself, :func:`~jsss.render.mesh.shadows_itself`) its directional shadow maps
    (:func:`~jsss.render.environment.environment_shadows`)."""
    if light.kind == "environment":
        maps = None
        if shadows_itself(mesh):
            maps = tuple(shadow_map(mesh, Light("directional", direction=tuple(-d)), size=VISIBILITY_MAP_SIZE)
                         for d in fibonacci_directions(VISIBILITY_DIRECTIONS))
        return environment_shadows(light, maps)
    lo, hi = mesh.bounds
    center = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2) * 1.02  # orthographic maps cover the bounding sphere
    if light.kind == "directional":
        view = OrthographicView(tuple(light.direction), tuple(center), 2 * radius, size)
        perspective = False
    else:
        position = np.asarray(light.position, float)
        axis = center - position
        rel = mesh.vertices - position
        cos = rel @ axis / np.maximum(np.linalg.norm(rel, axis=1) * np.linalg.norm(axis), 1e-300)
        half_angle = np.degrees(np.arccos(np.clip(cos.min(), -1, 1)))
        if np.linalg.norm(axis) == 0 or half_angle > 80:
            raise ValueError(f"point light at {np.round(position, 3).tolist()} sees the object over more than "
                             f"160 degrees (half angle {half_angle:.0f}); one shadow map cannot cover it -- "
                             "move the light further out.")
        view = PerspectiveView(tuple(position), tuple(center), min(2 * half_angle * 1.05 + 1, 170), size, size)
        perspective = True
    xy, depth = view.project(mesh.vertices)
    raster = rasterize(xy, depth, mesh.faces, (size, size), perspective=perspective)
    uv = surface_attributes(raster, mesh.faces, mesh.uvs)
    return ShadowMap(view, raster.depth, uv, raster.mask)


class LightGeometry(NamedTuple):
    """Per point (texel or pixel) and light: what the irradiance needs, and the TSM data.

    Attributes (arrays of the points' shape ``P``)
    ----------
    cosine : cos of the angle between normal and the direction to the light (may be < 0)
    falloff : 1/d^2 for a point light, 1 for a directional one
    visible : 1 where the light reaches the point (not shadowed), else 0
    thickness : distance light travelled inside the object to a shadowed point [mm]
    front_uv : (P, 2) UV where that light entered
    behind : 1 on shadowed points with a front point, else 0
    to_light : (P, 3) unit direction from the point to the light
    distance : distance to a point light [mm]; infinite for a directional one
    """

    cosine: np.ndarray
    falloff: np.ndarray
    visible: np.ndarray
    thickness: np.ndarray
    front_uv: np.ndarray
    behind: np.ndarray
    to_light: np.ndarray
    distance: np.ndarray | float = np.inf  # a geometry built without it reads as parallel light

    def astype(self, dtype) -> "LightGeometry":
        """The same geometry as ``jnp`` arrays of ``dtype`` (what the JAX passes read)."""
        return LightGeometry(*(jnp.asarray(a, dtype) for a in self))


def light_geometry(positions, normals, valid, light: Light, shadow: ShadowMap) -> LightGeometry:
    """Shadow test and thickness of ``positions`` (P, 3) against a light's shadow map (an
    environment's: :class:`~jsss.render.environment.EnvironmentGeometry`)."""
    if light.kind == "environment":
        seen = None
        if shadow.maps is not None:
            seen = []
            for d, m in zip(shadow.directions, shadow.maps):
                g = light_geometry(positions, normals, valid, Light("directional", direction=tuple(-d)), m)
                seen.append((g.cosine, g.visible))
        return environment_geometry(normals, valid, shadow, seen)
    positions = np.asarray(positions, float)
    valid = np.asarray(valid, bool)
    if light.kind == "directional":
        to_light = -np.asarray(light.direction, float) / np.linalg.norm(light.direction)
        to_light = np.broadcast_to(to_light, positions.shape)
        falloff = np.ones(positions.shape[:-1])
        distance = np.full(positions.shape[:-1], np.inf)
    else:
        offset = np.asarray(light.position, float) - positions
        dist2 = np.maximum((offset**2).sum(-1), 1e-12)
        to_light = offset / np.sqrt(dist2)[..., None]
        falloff = 1.0 / dist2
        distance = np.sqrt(dist2)
    cosine = np.where(valid, (np.asarray(normals) * to_light).sum(-1), 0.0)
    xy, depth = shadow.view.project(positions.reshape(-1, 3))
    n = shadow.depth.shape[0]
    ix = np.clip(np.floor(np.nan_to_num(xy[:, 0], nan=-1)), -1, n).astype(int)
    iy = np.clip(np.floor(np.nan_to_num(xy[:, 1], nan=-1)), -1, n).astype(int)
    inside = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n)
    ixc, iyc = np.clip(ix, 0, n - 1), np.clip(iy, 0, n - 1)
    front = np.where(inside, shadow.depth[iyc, ixc], np.inf)
    pixel = np.asarray(shadow.view.pixel_size(depth), float) * np.ones_like(depth)
    # Slope-scaled bias: a map pixel spans more depth where the surface is seen edge-on.
    tangent = np.sqrt(np.maximum(1 - cosine.reshape(-1) ** 2, 0)) / np.maximum(np.abs(cosine.reshape(-1)), 0.1)
    bias = pixel * (1.5 + tangent)
    shadowed = depth > front + bias
    found = shadowed & np.isfinite(front)
    shape = positions.shape[:-1]
    return LightGeometry(
        cosine=cosine,
        falloff=falloff,
        visible=(valid & ~shadowed.reshape(shape)).astype(float),
        thickness=np.where(found, depth - front, 0.0).reshape(shape),
        front_uv=np.where(found[:, None], shadow.front_uv[iyc, ixc], 0.0).reshape(shape + (2,)),
        behind=(valid & found.reshape(shape)).astype(float),
        to_light=np.array(to_light),
        distance=distance,
    )


def depth_falloff(g: LightGeometry, depth, dtype):
    r"""How much less of a point light reaches ``depth`` [mm] (shape ``C``) below each point than
    the point itself: :math:`d^2 / (d^2 + 2\delta d\cos\theta + \delta^2)`, its inverse square at a
    virtual point ``depth`` under the surface along the normal; 1 for a directional light.
    Shape ``P + C``.

    Light scatters below the surface, where a point light's rays have spread further: a flat
    half space under a point light at height h gets, where the light is overhead, the
    irradiance of a light at h + depth. Over an infinite plane the total is unchanged to first
    order in depth / h; the light moves outward from under the lamp.
    """
    d = jnp.asarray(g.distance, dtype)[..., None]
    finite = jnp.isfinite(d)
    d = jnp.where(finite, d, 1.0)  # double where: the directional branch must not see inf
    cos = jnp.clip(jnp.asarray(g.cosine, dtype), 0.0, 1.0)[..., None]
    depth = jnp.asarray(depth, dtype)
    return jnp.where(finite, d**2 / (d**2 + 2 * depth * d * cos + depth**2), 1.0)


def irradiance(lights: list[LightGeometry], radiant, eta, *, medium=None, deposit=None, law=None):
    """Light transmitted into the surface at each point (..., C).

    With ``medium`` (a homogeneous Medium) each light's share is scaled by how much more of it
    the half space returns for its angle than for a normal beam
    (:func:`jsss.diffusion.incidence.incidence_ratio`): the profiles are for normal incidence, so this
    is the irradiance a normal beam would need to return the same light. With ``deposit`` (a
    Medium) point lights are read at its deposit depth (:func:`depth_falloff`,
    :func:`jsss.diffusion.incidence.deposit_depth`).

    Parameters
    ----------
    lights : list of LightGeometry, or EnvironmentGeometry for an environment
        (:func:`jsss.render.environment.environment_irradiance`)
    radiant : array, shape (L, C)
        Each light's colour times intensity (differentiable).
    eta : array, shape (C,)
        Relative index of refraction of the material.
    law : callable, optional, keyword-only
        ``incidence_law(medium)`` solved already, in place of ``medium`` (normal filtering
        lights one frame three times, once per channel's normals, with one law).
    """
    if law is not None and medium is not None:
        raise ValueError("irradiance: pass medium (the law is solved here) or law (solved already), not both.")
    total = 0.0
    if medium is not None:
        law = incidence_law(medium)  # one H solve for every light
    for i, g in enumerate(lights):
        if isinstance(g, EnvironmentGeometry):  # parallel light from every direction: no deposit depth
            total = total + environment_irradiance(g, radiant[i], eta, law=law)
            continue
        cos = jnp.clip(jnp.asarray(g.cosine, radiant.dtype), 0.0, 1.0)
        transmitted = fresnel_transmittance(cos[..., None], eta)
        if law is not None:
            transmitted = transmitted * law(cos)
        if deposit is not None:
            transmitted = transmitted * depth_falloff(g, deposit_depth(deposit), radiant.dtype)
        weight = (cos * jnp.asarray(g.falloff * g.visible, radiant.dtype))[..., None]
        total = total + radiant[i] * weight * transmitted
    return total


def node_irradiance(lights: list[LightGeometry], radiant, eta, nodes, *, oblique: bool, deposit: bool):
    r"""Irradiance (..., K, C) as each basis node ``k`` of a parameter map receives it: with
    ``oblique`` scaled by node ``k``'s own oblique-incidence law, with ``deposit`` point lights
    read at its own deposit depth (:func:`irradiance` with ``nodes[k]``, a Medium of shape (K, C)).

    Where the medium varies over the surface, so do both: a texel of skin returns oblique light
    by another law, and scatters it at another depth, than a texel of marble beside it. A
    texel's light is then :math:`\sum_k a_k E_k` for its blend weights :math:`a_k`, the law of
    the blended profile (each node's profile meets its own law).
    """
    if not (oblique or deposit):  # every node receives the same light
        E = irradiance(lights, radiant, eta)
        return jnp.broadcast_to(E[..., None, :], E.shape[:-1] + (nodes.sigma_a.shape[0], E.shape[-1]))
    per_node = []
    for k in range(nodes.sigma_a.shape[0]):
        node = jax.tree_util.tree_map(lambda a, k=k: a[k], nodes)
        per_node.append(irradiance(lights, radiant, eta, medium=node if oblique else None,
                                   deposit=node if deposit else None))
    return jnp.stack(per_node, -2)


def _bilinear(texture, uv, mask):
    """Mask-normalised bilinear lookup of ``texture`` (..., S, S, C) at ``uv`` (P..., 2)."""
    size = texture.shape[-2]
    x = uv[..., 0] * size - 0.5
    y = uv[..., 1] * size - 0.5
    x0, y0 = jnp.floor(x), jnp.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(jnp.int32), y0.astype(jnp.int32)
    acc, weight = 0.0, 0.0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        xi = jnp.clip(x0 + dx, 0, size - 1)
        yi = jnp.clip(y0 + dy, 0, size - 1)
        m = mask[yi, xi] * w
        acc = acc + texture[..., yi, xi, :] * m[..., None]
        weight = weight + m
    has = weight > 1e-12
    return jnp.where(has[..., None], acc / jnp.where(has, weight, 1.0)[..., None], 0.0)


def lookup(texture, uv, mask):
    """Bilinear read of a texture (S, S, C) -- or a stack (n, S, S, C) -- at UVs, ignoring invalid texels."""
    return _bilinear(texture, jnp.asarray(uv, texture.dtype), jnp.asarray(mask, texture.dtype))


def translucent_transmission(blurred, weights, variances, lights: list[LightGeometry], mask):
    r"""Exitance at shadowed points from light that entered at their front points.

    Parameters
    ----------
    blurred : array, shape (n, S, S, C)
        Irradiance blurred by each Gaussian of the profile.
    weights : array, shape (n, C); variances : array, shape (n,) [mm^2]
    lights : list of LightGeometry (per texel)
    mask : array, shape (S, S)

    Returns
    -------
    array, shape (S, S, C): :math:`\sum_i w_i e^{-d^2/2v_i} (G_i * E)(x_{front})`.
    """
    total = 0.0
    for g in lights:
        if isinstance(g, EnvironmentGeometry):  # no single direction to cross the object along
            continue
        d2 = jnp.asarray(g.thickness, blurred.dtype) ** 2
        attenuation = jnp.exp(-d2[None] / (2 * variances[:, None, None]))  # (n, S, S)
        front = lookup(blurred, g.front_uv, mask)  # (n, S, S, C)
        per_gaussian = front * attenuation[..., None] * weights[:, None, None, :]
        total = total + per_gaussian.sum(0) * jnp.asarray(g.behind, blurred.dtype)[..., None]
    return total
