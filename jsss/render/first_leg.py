r"""The pass "first leg": light that enters obliquely is first scattered farther along its way.

A beam that enters at a slant crosses its first stretch below the surface along the refracted
ray, so the light it deposits sits, on average, a lateral

.. math:: \Delta_{f,c} = \frac{\sqrt{1 - \mu_0^2}}{\mu_0}\,\frac{\langle\tau\rangle_{f,c}}{\sigma'_{t,c}}
          \quad [\mathrm{mm}]

beyond the entry point along the light's tangential direction :math:`\hat t` (inside cosine
:math:`\mu_0`; :func:`jsss.diffusion.lateral_step.first_leg_step` derives the mean depth and
tests it against an independent random walk). The profiles are for normal incidence, with no
such step: with a translation-invariant profile the exitance of the moved deposits is the
profile's exitance read :math:`\Delta_f` back toward the light,
:math:`M(x) = M_0(x - \Delta_f\hat t)`, so the pass adds a step to where the pass "last leg"
reads the exitance (:mod:`jsss.render.last_leg`): the camera sees
:math:`M_0(x + \Delta_\ell\,\hat a - \Delta_f\,\hat t)` with :math:`\hat a` the direction away
from the eye. Several lights' steps are mixed by each light's share of the irradiance there.

The first leg's length spreads as a free path's, and at a rim the exitance is far from linear
over it: reading at the mean step alone leaves 0.1 of the light 0.25 mm inside a rim where
the walk below measures 0.28. So the exitance is averaged over ``FIRST_LEG_QUANTILE_COUNT``
points, the mean step times the midpoint quantiles of an exponential
(:func:`first_leg_quantiles`; 8 points moved the grazing frame below by < 0.2 %).

Under uniform light it moves nothing. It matters where the light changes over a first leg:
at an open surface's rim, where under a grazing light the light that would have entered
beyond the rim is missing (the planner's rule: :func:`jsss.render.planner.first_leg_decision`),
not under a lamp. There the steps fan out from the lamp's foot: the moved deposits thin out
(the move's divergence), which a read at a moved point leaves out, and on the ketchup plane
under its lamp the pass took red from 2.5 to 3.8 % per pixel against Mitsuba, its sum from
0.979 to 1.029. So only parallel light moves. Measured:

- a beam 25 degrees above an index-matched half space (albedo 0.75) against an independent
  random walk across the rim it comes from (``tests/jsss/render/test_first_leg_pass.py``):
  the default frame within 0.1 of the walk's relative radiance in every 0.5 mm bin (0.07-0.08
  at 0.75-1.25 mm; 0.39 off without the pass);
- ``benchmarks/calibration_scenes/ketchup_grazing.toml`` against Mitsuba
  (``benchmarks/lateral_exit.py --black-walls``): red 10.8 % per pixel with neither leg's
  pass, 3.3 % with both (the path tracer's noise taken out).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..diffusion.lateral_step import first_leg_step
from ..fresnel import fresnel_transmittance
from ..numerics import safe_sqrt
from .environment import EnvironmentGeometry, environment_irradiance

__all__ = ["FIRST_LEG_QUANTILE_COUNT", "along_the_light", "first_leg_moves", "first_leg_quantiles"]

FIRST_LEG_QUANTILE_COUNT = 4  # lookups that stand for the first leg's spread (8 moved the grazing frame by < 0.2 %)


def first_leg_quantiles(count: int) -> np.ndarray:
    """``count`` multiples of the mean first leg that stand for its spread: the midpoint
    quantiles of an exponential free path, scaled to mean 1 (4: 0.146, 0.513, 1.070, 2.271)."""
    q = -np.log(1 - (np.arange(count) + 0.5) / count)
    return q / q.mean()


def along_the_light(normal, to_light):
    """Unit tangent (..., 3) along which light from ``to_light`` travels at each point: minus the
    part of the direction to the light in the tangent plane; zero at normal incidence. JAX."""
    tangential = -(to_light - (to_light * normal).sum(-1, keepdims=True) * normal)
    length = safe_sqrt((tangential**2).sum(-1, keepdims=True))
    ok = length > 1e-9
    return jnp.where(ok, tangential / jnp.where(ok, length, 1.0), 0.0)


def first_leg_moves(medium, normal, view, lights, radiant, eta, dtype):
    """Mean displacement [mm] (..., C, 3) of the light's first leg at each point, for the light
    that leaves toward the camera: each light's step (:func:`first_leg_step`, every order's)
    along its tangential direction, weighted by its share of the transmitted irradiance. Parallel
    (directional) lights only: a point light adds to the irradiance without a step (module
    docstring).

    ``normal``, ``view`` (..., 3) unit vectors (the view toward the eye); ``lights`` the lights
    at the points (:class:`~jsss.render.lighting.LightGeometry`, or an
    :class:`~jsss.render.environment.EnvironmentGeometry`, which lights from every side and
    adds to the irradiance without a step); ``radiant`` (L, C); ``eta`` (C,). JAX, in
    ``dtype``, differentiable in the medium."""
    normal, view = jnp.asarray(normal, dtype), jnp.asarray(view, dtype)
    cos_view = jnp.clip((normal * view).sum(-1), 0.0, 1.0)
    total, moved = 0.0, 0.0
    for i, g in enumerate(lights):
        if isinstance(g, EnvironmentGeometry):
            total = total + environment_irradiance(g.astype(dtype), radiant[i], eta)
            continue
        cos = jnp.clip(jnp.asarray(g.cosine, dtype), 0.0, 1.0)
        share = radiant[i] * (cos * jnp.asarray(g.falloff, dtype) * jnp.asarray(g.visible, dtype))[..., None] \
            * fresnel_transmittance(cos[..., None], eta)                                    # (..., C)
        step = first_leg_step(medium, cos, cos_view)                                         # (..., C) mm
        # Parallel light only: a point light's steps fan out from its foot, which spreads the
        # deposits (the move's divergence) as a read at a moved point does not
        parallel = jnp.isinf(jnp.asarray(g.distance, dtype))
        step = jnp.where(parallel[..., None], step, 0.0)
        direction = along_the_light(normal, jnp.asarray(g.to_light, dtype))                  # (..., 3)
        total = total + share
        moved = moved + (share * step)[..., None] * direction[..., None, :]
    if isinstance(moved, float):  # no light with a direction
        return jnp.zeros(normal.shape[:-1] + (jnp.shape(radiant)[-1], 3), dtype)
    ok = total > 0
    return jnp.where(ok[..., None], moved / jnp.where(ok, total, 1.0)[..., None], 0.0)
