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

import warnings
from dataclasses import dataclass
from pathlib import Path
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
    direction_radiance,
    environment_geometry,
    environment_irradiance,
    environment_shadows,
    fibonacci_directions,
)
from .kept import save_arrays
from .mesh import Mesh, shadows_itself
from .raster import OrthographicView, PerspectiveView, rasterize, surface_attributes

__all__ = ["Light", "LightGeometry", "ShadowMap", "irradiance", "keep_visibility_maps_in", "light_geometry",
           "node_irradiance", "shadow_map", "translucent_transmission", "visibility_maps"]


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
    """Depth and front-surface UV as seen from a light (``front_uv`` None: depth only, as an
    environment's visibility maps need)."""

    view: OrthographicView | PerspectiveView
    depth: np.ndarray
    front_uv: np.ndarray | None
    mask: np.ndarray


def shadow_map(mesh: Mesh, light: Light, *, size: int = 512, with_uv: bool = True) -> ShadowMap:
    """Rasterize ``mesh`` from ``light``: an orthographic map for directional lights, a perspective one for points.

    For an :class:`~jsss.render.environment.Environment`, its tables and (where the mesh can
    shadow itself, :func:`~jsss.render.mesh.shadows_itself`) its directional shadow maps
    (:func:`~jsss.render.environment.environment_shadows`)."""
    if light.kind == "environment":
        return environment_shadows(light, visibility_maps(mesh) if shadows_itself(mesh) else None)
    view, perspective = _light_view(mesh, light, size)
    xy, depth = view.project(mesh.vertices)
    raster = rasterize(xy, depth, mesh.faces, (size, size), perspective=perspective)
    uv = surface_attributes(raster, mesh.faces, mesh.uvs) if with_uv else None
    return ShadowMap(view, raster.depth, uv, raster.mask)


def _light_view(mesh: Mesh, light: Light, size: int):
    """The view a light's shadow map is rasterized in, and whether it is a perspective one."""
    lo, hi = mesh.bounds
    center = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2) * 1.02  # orthographic maps cover the bounding sphere
    if light.kind == "directional":
        return OrthographicView(tuple(light.direction), tuple(center), 2 * radius, size), False
    position = np.asarray(light.position, float)
    axis = center - position
    rel = mesh.vertices - position
    cos = rel @ axis / np.maximum(np.linalg.norm(rel, axis=1) * np.linalg.norm(axis), 1e-300)
    half_angle = np.degrees(np.arccos(np.clip(cos.min(), -1, 1)))
    if np.linalg.norm(axis) == 0 or half_angle > 80:
        raise ValueError(f"point light at {np.round(position, 3).tolist()} sees the object over more than "
                         f"160 degrees (half angle {half_angle:.0f}); one shadow map cannot cover it -- "
                         "move the light further out.")
    return PerspectiveView(tuple(position), tuple(center), min(2 * half_angle * 1.05 + 1, 170), size, size), True


# Where visibility_maps keeps an environment's shadow maps on disk: None (the library's default)
# keeps them in memory only; console scripts name a folder with keep_visibility_maps_in.
_visibility_dir: Path | None = None
_visibility_in_memory: dict = {}  # (mesh digest, directions, size) -> maps, the last few meshes
_VISIBILITY_MESHES = 4


def keep_visibility_maps_in(folder) -> None:
    """Keep environments' visibility maps under ``folder/visibility/`` from now on (console
    scripts; None: memory only)."""
    global _visibility_dir
    _visibility_dir = None if folder is None else Path(folder)


def visibility_maps(mesh: Mesh) -> tuple[ShadowMap, ...]:
    """The ``VISIBILITY_DIRECTIONS`` directional depth maps (``VISIBILITY_MAP_SIZE`` square, toward
    :func:`~jsss.render.environment.fibonacci_directions`) an environment's visibility is read
    from: once per mesh. Kept for the process (the last 4 meshes) and, where
    :func:`keep_visibility_maps_in` named a folder, on disk as
    ``visibility/<mesh digest>-<directions>-<size>.npz`` (the head's 96 maps: 1.6 s to
    rasterize)."""
    directions = fibonacci_directions(VISIBILITY_DIRECTIONS)
    key = (mesh.digest(), VISIBILITY_DIRECTIONS, VISIBILITY_MAP_SIZE)
    if key in _visibility_in_memory:
        return _visibility_in_memory[key]
    lights = [Light("directional", direction=tuple(-d)) for d in directions]
    path = None if _visibility_dir is None else _visibility_dir / "visibility" / ("-".join(map(str, key)) + ".npz")
    maps = None
    if path is not None and path.is_file():
        try:
            with np.load(path) as kept:
                depth, mask = kept["depth"], kept["mask"]
            views = [_light_view(mesh, light, VISIBILITY_MAP_SIZE)[0] for light in lights]
            maps = tuple(ShadowMap(v, d, None, m) for v, d, m in zip(views, depth, mask, strict=True))
        except (OSError, ValueError, KeyError, EOFError) as error:
            warnings.warn(f"{path}: unreadable visibility maps ({error}); computing them again", stacklevel=2)
            maps = None
    if maps is None:
        maps = tuple(shadow_map(mesh, light, size=VISIBILITY_MAP_SIZE, with_uv=False) for light in lights)
        if path is not None:
            _write_maps(path, maps)
    if len(_visibility_in_memory) >= _VISIBILITY_MESHES:
        _visibility_in_memory.pop(next(iter(_visibility_in_memory)))
    _visibility_in_memory[key] = maps
    return maps


def _write_maps(path: Path, maps) -> None:
    try:
        save_arrays(path, {"depth": np.stack([m.depth for m in maps]), "mask": np.stack([m.mask for m in maps])},
                    compressed=True)
    except OSError as error:  # a read-only cache folder must not stop a render
        warnings.warn(f"{path}: cannot keep the visibility maps there ({error})", stacklevel=3)


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
        visible = None if shadow.maps is None else _visible_share(positions, normals, valid, shadow)
        return environment_geometry(normals, valid, shadow, visible)
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
    depth, front, shadowed, (iyc, ixc) = _depth_test(positions.reshape(-1, 3), cosine.reshape(-1), shadow)
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


def _depth_test(positions, cosine, shadow: ShadowMap):
    """Flat points (P, 3) with their cosines (P,) against a shadow map: depth along the light,
    the map's front depth there (inf outside it), shadowed (P,) and the map texel (rows, cols)."""
    xy, depth = shadow.view.project(positions)
    n = shadow.depth.shape[0]
    ix = np.clip(np.floor(np.nan_to_num(xy[:, 0], nan=-1)), -1, n).astype(int)
    iy = np.clip(np.floor(np.nan_to_num(xy[:, 1], nan=-1)), -1, n).astype(int)
    inside = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n)
    ixc, iyc = np.clip(ix, 0, n - 1), np.clip(iy, 0, n - 1)
    front = np.where(inside, shadow.depth[iyc, ixc], np.inf)
    pixel = np.asarray(shadow.view.pixel_size(depth), float) * np.ones_like(depth)
    return depth, front, depth > front + _slope_bias(pixel, cosine), (iyc, ixc)


def _slope_bias(pixel, cosine):
    """How much nearer than the map's front a point may lie and still count as lit: 1.5 map
    texels, more where the surface is seen edge-on (a texel spans more depth there)."""
    tangent = np.sqrt(np.maximum(1 - cosine**2, 0)) / np.maximum(np.abs(cosine), 0.1)
    return pixel * (1.5 + tangent)


def _visible_share(positions, normals, valid, shadows) -> np.ndarray:
    """Each point's visible share of an environment (P...; 1 unshadowed, 0 on invalid points):
    its cosine-weighted light over the directional maps that see it, over all of it
    (:func:`~jsss.render.environment.environment_geometry`).

    Each map is tested only where its direction is above the surface (below, the light counts
    for nothing), with percentage-closer filtering: the depth test at the four map texels
    around the point, weighted bilinearly. At the nearest texel alone, each coarse map cut its
    shadow's edge into texel-sized steps, and the sum of 96 of them showed as blocks in the
    head's eye sockets. Computed in float32 over the valid points only (depths of a few hundred
    mm against a bias of 1.5 map texels): 0.6 s for the head's 240 000 texels, 1.4 s in
    float64 over every point with a full shadow test per map.
    """
    shape = np.shape(valid)
    valid = np.asarray(valid, bool).reshape(-1)
    points = np.asarray(positions, np.float32).reshape(-1, 3)[valid]
    normal = np.asarray(normals, np.float32).reshape(-1, 3)[valid]
    lit_sum = np.zeros(len(points), np.float32)
    total = np.zeros(len(points), np.float32)
    for toward, radiance, shadow in zip(shadows.directions, direction_radiance(shadows), shadows.maps):
        cosine = normal @ np.asarray(toward, np.float32)
        above = np.flatnonzero(cosine > 0)
        share = np.float32(radiance) * cosine[above]
        total[above] += share
        lit_sum[above] += share * _filtered_visibility(points[above], cosine[above], shadow)
    share = np.zeros(valid.shape)
    share[valid] = np.where(total > 0, lit_sum / np.where(total > 0, total, 1), 1)
    return share.reshape(shape)


def _filtered_visibility(points, cosine, shadow: ShadowMap) -> np.ndarray:
    """Percentage-closer filtering of one directional map at ``points`` (N, 3), float32: 0 to 1.
    The map is padded by one texel of infinite depth (nothing in front), so the four taps are
    plain gathers from the flat array."""
    view = shadow.view
    right, down, forward = (np.asarray(a, np.float32) for a in view.frame())
    scale = np.float32(view.size / view.extent)
    rel = points - np.asarray(view.center, np.float32)
    depth = rel @ forward + np.float32(view.extent)
    x = (rel @ right) * scale + np.float32(view.size / 2 + 0.5)  # texel centres at integers, +1 for the pad
    y = (rel @ down) * scale + np.float32(view.size / 2 + 0.5)
    n = shadow.depth.shape[0] + 2
    x0 = np.clip(np.floor(x), 0, n - 2)
    y0 = np.clip(np.floor(y), 0, n - 2)
    fx, fy = np.clip(x - x0, 0, 1), np.clip(y - y0, 0, 1)
    corner = y0.astype(np.int64) * n + x0.astype(np.int64)
    front = np.pad(shadow.depth.astype(np.float32), 1, constant_values=np.inf).ravel()
    reach = depth - _slope_bias(np.float32(view.pixel_size()), cosine)  # the depth less the bias
    top = (1 - fx) * (reach <= front[corner]) + fx * (reach <= front[corner + 1])
    bottom = (1 - fx) * (reach <= front[corner + n]) + fx * (reach <= front[corner + n + 1])
    return (1 - fy) * top + fy * bottom


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
