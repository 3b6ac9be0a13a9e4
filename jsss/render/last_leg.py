r"""The pass "last leg": the camera reads the exitance where the light it sees was last scattered.

The light that leaves a point toward the camera crossed its last stretch below the surface
along the refracted view ray, so it was last scattered under a point farther from the camera,
on average by

.. math:: \Delta_c = \frac{\sqrt{1 - \mu^2}}{\mu}\,\frac{\langle\tau\rangle_c}{\sigma'_{t,c}}
          \quad [\mathrm{mm}]

with the inside view cosine :math:`\mu` and the mean depth :math:`\langle\tau\rangle` of
Chandrasekhar's kernel for the light that arrives at the point
(:meth:`jsss.diffusion.exit_law.ExitLaw.last_leg_depth`; :mod:`jsss.diffusion.lateral_step`
derives it and tests it against an independent random walk). Where the exitance changes over
a few transport mean free paths (under a near lamp, at a shadow's or a plane's edge) the
camera sees that farther point's light: texture space looks each channel's exitance up
:math:`\Delta_c` along the surface, away from the eye (:func:`moved_lookup`), and scales the
first bounce, computed at the pixel, by the same ratio (:func:`moved_ratio`): the step is that of
every order, so the whole subsurface light moves. The brute-force reference integrates the profile around the
shifted point (:func:`jsss.render.reference.reference_radiance`).

Measured against Mitsuba 3 on the ketchup plane (``benchmarks/lateral_exit.py``), the red
channel (step 1.6-2.7 mm) is where it matters; it moves no total under uniform light. Only the
mean step is taken: the spread of the last leg's lateral step about its mean is a blur of a
fraction of a transport length, far below the profile's own.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..diffusion.exit_law import exit_law
from ..numerics import interpolate_rows, safe_sqrt
from .lighting import lookup
from .raster import Raster
from .shading import exit_weights

__all__ = ["away_from_eye", "last_leg_steps", "moved_lookup", "moved_ratio", "tabulated_steps",
           "uv_jacobians", "uv_per_mm_away_from_eye"]


def away_from_eye(normal, view) -> np.ndarray:
    """Unit tangent (..., 3) at each point pointing away from the eye: minus the view
    direction's part in the tangent plane; zero where the camera looks straight down the
    normal (no step). ``normal``, ``view`` (..., 3) unit vectors, the view toward the eye."""
    normal, view = np.asarray(normal, float), np.asarray(view, float)
    tangential = -(view - (view * normal).sum(-1, keepdims=True) * normal)
    length = np.linalg.norm(tangential, axis=-1, keepdims=True)
    return np.where(length > 1e-9, tangential / np.maximum(length, 1e-12), 0.0)


def uv_jacobians(vertices, faces, uvs, raster: Raster) -> np.ndarray:
    """How far the UV moves per mm walked along the surface, per pixel (H, W, 2, 3) [1/mm]: a
    tangent step :math:`t` [mm] moves the pixel's UV by ``J @ t``.

    Per triangle, :math:`\\partial P/\\partial(u, v)` (3 x 2) from its corners; ``J`` is its
    least-squares preimage :math:`(J_P^TJ_P)^{-1}J_P^T`. Zero where no triangle covers the pixel
    or the triangle's UVs are degenerate. NumPy: geometry alone."""
    vertices, faces, uvs = np.asarray(vertices, float), np.asarray(faces), np.asarray(uvs, float)
    corners, uv_corners = vertices[faces], uvs[faces]                          # (F, 3, 3), (F, 3, 2)
    edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], -1)   # (F, 3, 2)
    uv_edges = np.stack([uv_corners[:, 1] - uv_corners[:, 0], uv_corners[:, 2] - uv_corners[:, 0]], -1)  # (F, 2, 2)
    det = np.linalg.det(uv_edges)
    ok = np.abs(det) > 1e-14
    safe = np.where(ok[:, None, None], uv_edges, np.eye(2))
    jacobian = edges @ np.linalg.inv(safe)                                      # (F, 3, 2): dP/d(u, v)
    gram = np.einsum("fki,fkj->fij", jacobian, jacobian)
    gram_ok = ok & (np.abs(np.linalg.det(gram)) > 1e-20)
    pinv = np.linalg.inv(np.where(gram_ok[:, None, None], gram, np.eye(2))) @ np.swapaxes(jacobian, 1, 2)  # (F, 2, 3)
    pinv = np.where(gram_ok[:, None, None], pinv, 0.0)
    face = np.where(raster.mask, raster.face, 0)
    return np.where(raster.mask[..., None, None], pinv[face], 0.0)


def uv_per_mm_away_from_eye(vertices, faces, uvs, raster: Raster, normal, view) -> np.ndarray:
    """How far the UV moves per mm walked along the surface away from the eye (H, W, 2) [1/mm]
    (:func:`uv_jacobians` times :func:`away_from_eye`). NumPy: geometry alone."""
    step = np.einsum("hwij,hwj->hwi", uv_jacobians(vertices, faces, uvs, raster), away_from_eye(normal, view))
    return np.where(raster.mask[..., None], step, 0.0)


DEPTH_NODES = 257  # outside exit cosines on which the kernel and its slope are tabulated per frame


def last_leg_steps(medium, normal, view, lights, radiant, dtype, *, first_bounce_apart: bool):
    """Mean step [mm] (..., C) of each point's last leg away from the eye, for the light that
    arrives at it: ``normal`` and ``view`` (..., 3) unit vectors (the view toward the eye),
    ``lights`` the lights at the points (:class:`~jsss.render.lighting.LightGeometry` or
    :class:`~jsss.render.environment.EnvironmentGeometry`), ``radiant`` (L, C); of the multiply
    scattered light when the first bounce is rendered apart. JAX, in ``dtype``, differentiable
    in the medium.

    :meth:`~jsss.diffusion.exit_law.ExitLaw.last_leg_depth`'s kernels and slopes depend on the
    exit cosine alone: they are evaluated on ``DEPTH_NODES`` cosines and interpolated linearly
    (its Nystrom sums at every pixel took 140 ms of a 320 x 240 frame, the table 60-70 ms;
    within 0.1 % of it, tested), then mixed by each point's light."""
    law = exit_law(medium, first_bounce_apart=first_bounce_apart)
    cos_view = jnp.asarray((jnp.asarray(normal, dtype) * jnp.asarray(view, dtype)).sum(-1), dtype)
    weights = exit_weights(law, [g.astype(dtype) for g in lights], radiant, law.eta)
    return tabulated_steps(law, medium, cos_view, weights)


def tabulated_steps(law, medium, cos_view, weights):
    """:func:`last_leg_steps` from the exit law ``law`` of ``medium``, the outside view cosines
    ``cos_view`` (...) and the node weights (..., C, K + 1) of the light at each point."""
    dtype = weights.dtype
    kernel, slope, inside = law.last_leg_table(jnp.linspace(0.0, 1.0, DEPTH_NODES, dtype=dtype))
    position = jnp.clip(cos_view, 0.0, 1.0) * (DEPTH_NODES - 1)
    kernel, slope = interpolate_rows(position, kernel), interpolate_rows(position, slope)   # (..., C, K + 1)
    mu = interpolate_rows(position, inside)                                                 # (..., C)
    depth = law.mixed_depth(mu, kernel, slope, weights)
    sigma_t = jnp.asarray(medium.sigma_a, dtype) + jnp.asarray(medium.sigma_s_prime, dtype)
    return safe_sqrt(jnp.maximum(1 - mu**2, 0.0)) / mu * depth / sigma_t


def moved_lookup(texture, pixel_uv, uv_moves, mask):
    """The texture (..., S, S, C) read, channel by channel, at each pixel's UV plus that
    channel's move ``uv_moves`` (H, W, C, 2) (bilinear, invalid texels left out as in
    :func:`jsss.render.lighting.lookup`); (..., H, W, C)."""
    dtype = texture.dtype
    pixel_uv, uv_moves = jnp.asarray(pixel_uv, dtype), jnp.asarray(uv_moves, dtype)
    channels = [lookup(texture[..., c:c + 1], pixel_uv + uv_moves[..., c, :], mask)
                for c in range(texture.shape[-1])]
    return jnp.concatenate(channels, -1)


def moved_ratio(moved, exitance):
    """``moved / exitance`` (..., C), 1 where no light is read at the pixel: how much the light
    read at the moved point differs from the pixel's own, which the first bounce's radiance and
    exitance (computed at the pixel) are scaled by, so that the whole subsurface light moves."""
    ok = exitance > 0
    return jnp.where(ok, moved / jnp.where(ok, exitance, 1.0), 1.0)
