r"""How much light a half space returns when it arrives obliquely: Chandrasekhar's H function.

The profiles (dipole, transport tables) are for light arriving along the normal. Light that
arrives at a grazing angle is deposited nearer the surface and more of it comes back out:
for isotropic scattering with albedo :math:`\omega` in an index-matched half space the total
reflectance per unit entering flux is exactly (Chandrasekhar 1960, *Radiative Transfer*, ch. IV)

.. math:: A(\mu_0) = 1 - H(\mu_0)\,\sqrt{1 - \omega},

with :math:`\mu_0` the cosine of the incoming direction and :math:`H` the solution of

.. math:: \frac{1}{H(\mu)} = \sqrt{1 - \omega}
          + \frac{\omega}{2}\int_0^1 \frac{\mu'\,H(\mu')}{\mu + \mu'}\,d\mu'.

At :math:`\omega = 0.75` (ketchup's red) :math:`A` grows from 0.243 at normal incidence to
0.283 at :math:`\mu_0 = 0.7` and 0.319 at 0.5: a renderer that scales every irradiance by the
normal-incidence total is 17-31 % short there. At :math:`\omega = 0.999` (marble) the growth
is 1.6-2.7 %.

The renderer uses the ratio :math:`A(\mu)/A(1)` with the similarity albedo
:math:`\sigma_s'/\sigma_t'` (the model the profiles are given in). Behind a Fresnel boundary it
takes the refracted cosine, which ignores the boundary's internal reflections; those make the
returning light more diffuse, so the ratio is then an upper bound on the growth
(``tests/jsss/test_incidence.py`` measures both against random walks at oblique incidence:
exact at eta 1, 1.6-2.8 points high at 66 degrees behind eta 1.3 and 1.5).

The renderer takes only the total from here. The *angle* at which the multiply scattered light
leaves still follows the exit lobe of :mod:`jsss.render.shading`, not the
:math:`H(\mu)H(\mu_0)` shape of the whole reflection of an index-matched half space
(:func:`index_matched_brdf`): with the transport profile and this law, Lambert frames of such a
plane (albedo 0.747) are -0.8 to +5.6 % off it at four view and light angles, where Mitsuba's
frames agree with it to 0.07 % (``benchmarks/transport_truth.py --chandrasekhar``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..medium import Medium
from ..numerics import (
    as_float_array,
    device_array,
    interpolate_rows,
    is_concrete,
    safe_sqrt,
)

__all__ = ["deposit_depth", "h_function", "h_function_numpy", "incidence_law", "incidence_ratio", "index_matched_brdf", "plane_albedo",
           "point_light_loss"]

NODES = 48          # Gauss-Legendre nodes on [0, 1]
ITERATIONS = 30     # steps of the 1/H form first: it converges geometrically, slowly near albedo 1
NEWTON_STEPS = 8    # then Newton on the nodes' equations: to 1e-15 at every albedo up to 1 - 1e-12 (the
                    # 1/H form alone, 400 steps, overshot: H(1) = 3.92 at albedo 1 - 1e-6 for 2.903). They were
                    # out from 12-05 to 12-07, blamed for CI workers' segfaults that were the workers'
                    # memory maps running out (measure.commands._console.release_compiled_programs)


def _nodes(dtype):
    x, w = np.polynomial.legendre.leggauss(NODES)
    return jnp.asarray((x + 1) / 2, dtype), jnp.asarray(w / 2, dtype)


def _albedo_margin(dtype) -> float:
    """How far below 1 an albedo is held (:func:`largest_albedo`): 1e-12, or 8 float32 steps."""
    return max(1e-12, 8 * float(np.finfo(dtype).eps))


def largest_albedo(albedo, dtype):
    r"""``albedo`` held below 1 by :func:`_albedo_margin`, where the H equation's root term
    :math:`\sqrt{1 - \omega}` has an infinite slope: 1 - 1e-12 changes H by 1e-6; in float32,
    where 1 - 1e-12 is 1, the margin is 9.5e-7 and H(1) is 2.9029 for albedo 1's 2.9078."""
    return jnp.minimum(albedo, jnp.asarray(1 - _albedo_margin(dtype), dtype))


def _solve_small(A, b):
    """``x`` with ``A x = b`` for small systems, batched (A (..., n, n), b (..., n)): Gaussian
    elimination with partial pivoting in plain array operations. ``jnp.linalg.solve`` calls
    LAPACK, and the first LAPACK call of a process loads SciPy's BLAS (0.12 s): with it in
    h_function's Newton steps, the render command's cold start went from 2.70x to 3.06x
    ``import jax`` (marble, 2026-12-07)."""
    n = A.shape[-1]
    rows = jnp.arange(n)
    M = jnp.concatenate([A, b[..., None]], axis=-1)                          # (..., n, n + 1)

    def eliminate(k, M):
        column = jnp.where(rows >= k, jnp.abs(M[..., :, k]), -1.0)
        pivot = jax.nn.one_hot(jnp.argmax(column, axis=-1), n, dtype=M.dtype)   # (..., n)
        at_k = (rows == k).astype(M.dtype)
        row_k, row_p = M[..., k, :], jnp.einsum("...i,...ij->...j", pivot, M)
        M = M + (at_k - pivot)[..., :, None] * (row_p - row_k)[..., None, :]    # swap rows k and p
        factor = jnp.where(rows > k, M[..., :, k] / M[..., k, k][..., None], 0.0)
        return M - factor[..., :, None] * M[..., k, :][..., None, :]

    M = jax.lax.fori_loop(0, n, eliminate, M)

    def substitute(i, x):
        k = n - 1 - i
        return x.at[..., k].set((M[..., k, n] - (M[..., k, :n] * x).sum(-1)) / M[..., k, k])

    return jax.lax.fori_loop(0, n, substitute, jnp.zeros(b.shape, M.dtype))


@jax.jit
def _h_on_nodes(albedo):
    """H on the Gauss-Legendre nodes, C + (NODES,), for held albedos ``albedo`` (C): the 1/H
    iteration, then Newton. Jitted once here: called eagerly (a frame's exit law solves it
    twice), the loops were traced again at every call, 340 ms each with the Newton steps."""
    dtype = albedo.dtype
    nodes, weights = _nodes(dtype)
    root = safe_sqrt(jnp.maximum(1 - albedo, 0.0))[..., None]              # C + (1,)
    half = (albedo / 2)[..., None]
    kernel = nodes[None, :] * weights[None, :] / (nodes[:, None] + nodes[None, :])  # (nodes, nodes)

    def step(_, H):
        return 1.0 / (root + half * (H[..., None, :] * kernel).sum(-1))

    def newton(_, H):
        g = root + half * (H[..., None, :] * kernel).sum(-1)                    # 1/H's right side
        jacobian = jnp.eye(NODES, dtype=dtype) * g[..., None] + half[..., None] * H[..., :, None] * kernel
        return H - _solve_small(jacobian, H * g - 1)

    H = jax.lax.fori_loop(0, ITERATIONS, step, jnp.ones(albedo.shape + (NODES,), dtype))
    return jax.lax.fori_loop(0, NEWTON_STEPS, newton, H)


def h_function(albedo, mu):
    r"""Chandrasekhar's H function for isotropic scattering, :math:`H(\mu)` at ``mu`` in [0, 1].

    ``albedo`` (shape ``C``) in [0, 1]; ``mu`` (shape ``S``) broadcast against it: the result
    has shape ``S + C``. Solved on Gauss-Legendre nodes by iterating the :math:`1/H` form, then
    by Newton steps on the nodes' equations (a fixed number of each, so ``jax.grad`` goes
    through them), then extended to ``mu`` by the same equation (Nystrom). The moment identity
    :math:`\int_0^1 H\,d\mu = (2/\omega)(1 - \sqrt{1-\omega})` holds to 1e-7 at every albedo
    and :math:`H(1)` = 2.90781 at albedo 1 (Chandrasekhar's closed integral);
    an albedo of 1 is taken as :math:`1 - 10^{-12}`, in float32 :math:`1 - 9.5\cdot 10^{-7}`
    (the iteration has no fixed scale there: :func:`largest_albedo`).
    """
    mu = as_float_array(mu)
    dtype = jnp.result_type(as_float_array(albedo), mu)
    albedo = largest_albedo(jnp.asarray(as_float_array(albedo), dtype), dtype)
    nodes, weights = _nodes(dtype)
    root = safe_sqrt(jnp.maximum(1 - albedo, 0.0))[..., None]              # C + (1,)
    half = (albedo / 2)[..., None]
    H = _h_on_nodes(albedo)
    # At mu: 1/H(mu) = root + albedo/2 sum_j w_j mu_j H_j / (mu + mu_j); mu = 0 gives H = 1.
    flat = mu.reshape(-1)
    terms = (weights * nodes) / (flat[:, None] + nodes[None, :])             # (S, nodes)
    inverse = root[None, ..., 0] + half[None, ..., 0] * jnp.einsum("sj,...j->s...", terms, H)
    return (1.0 / inverse).reshape(mu.shape + albedo.shape)


def h_function_numpy(albedo, mu) -> np.ndarray:
    """:func:`h_function` step by step in NumPy (the same nodes, iterations and extension), in
    the dtype of ``albedo`` (an array): for the planner, which would otherwise lower each JAX op
    as its own small program. Shape ``S + C``."""
    albedo = np.asarray(albedo)
    dtype = albedo.dtype
    mu = np.asarray(mu, dtype)
    x, w = np.polynomial.legendre.leggauss(NODES)
    nodes, weights = ((x + 1) / 2).astype(dtype), (w / 2).astype(dtype)
    capped = np.minimum(albedo, dtype.type(1 - _albedo_margin(dtype)))
    root = np.sqrt(np.maximum(1 - capped, 0.0))[..., None]
    half = (capped / 2)[..., None]
    kernel = nodes[None, :] * weights[None, :] / (nodes[:, None] + nodes[None, :])
    H = np.ones(capped.shape + (NODES,), dtype)
    for _ in range(ITERATIONS):
        H = 1.0 / (root + half * (H[..., None, :] * kernel).sum(-1))
    for _ in range(NEWTON_STEPS):
        g = root + half * (H[..., None, :] * kernel).sum(-1)
        jacobian = np.eye(NODES, dtype=dtype) * g[..., None] + half[..., None] * H[..., :, None] * kernel
        H = H - np.linalg.solve(jacobian, (H * g - 1)[..., None])[..., 0]
    terms = (weights * nodes) / (mu.reshape(-1)[:, None] + nodes[None, :])
    inverse = root[None, ..., 0] + half[None, ..., 0] * np.einsum("sj,...j->s...", terms, H)
    return (1.0 / inverse).reshape(mu.shape + capped.shape)


def plane_albedo(albedo, mu):
    r"""Total reflectance :math:`1 - H(\mu)\sqrt{1-\omega}` of an index-matched half space for
    light arriving at cosine ``mu`` (all orders of scattering, per unit entering flux). Shape
    ``S + C`` as :func:`h_function`."""
    albedo = as_float_array(albedo)
    return 1.0 - h_function(albedo, mu) * safe_sqrt(jnp.maximum(1 - albedo, 0.0))


def index_matched_brdf(albedo, cos_incident, cos_exit):
    r"""The whole reflection (every order of scattering) of a uniformly lit, index-matched half
    space with isotropic scattering, as a BRDF [1/sr] (Chandrasekhar 1960, eq. IV.(29)):

    .. math:: f_r(\mu, \mu_0) = \frac{\omega\,H(\mu)\,H(\mu_0)}{4\pi\,(\mu + \mu_0)},

    the single-scattering BRDF times :math:`H(\mu)H(\mu_0)`; it does not depend on the
    azimuth. ``albedo`` (shape ``C``); the cosines broadcast together (shape ``S``); the
    result is ``S + C``. A closed-form truth for a path tracer's frames of a large flat
    object (``benchmarks/transport_truth.py``) and the far field of the profiles.
    """
    albedo = as_float_array(albedo)
    cos_incident, cos_exit = jnp.broadcast_arrays(as_float_array(cos_incident), as_float_array(cos_exit))
    both = jnp.stack([cos_incident, cos_exit])
    H = h_function(albedo, both)
    n = len(jnp.shape(albedo))
    path = (cos_incident + cos_exit).reshape(cos_incident.shape + (1,) * n)
    return albedo * H[0] * H[1] / (4 * jnp.pi * path)


def incidence_law(medium: Medium):
    r"""The oblique-incidence law of ``medium`` as a function of the outside cosine: see
    :func:`incidence_ratio`, which it evaluates. The H solve (per channel) is done here, once;
    the returned function only refracts and interpolates, so a renderer calls this once per
    frame and the result once per light.
    """
    eta = medium.eta
    albedo = medium.sigma_s_prime / (medium.sigma_a + medium.sigma_s_prime)
    n = len(jnp.shape(albedo))
    # A frame has ~10^5 points: A is evaluated on 257 cosines and interpolated linearly (within
    # 1e-6 of it: A is smooth in mu). The grid ends at 1, so its last row is normal incidence.
    grid = jnp.linspace(0.0, 1.0, 257, dtype=albedo.dtype)
    table = plane_albedo(albedo, grid).reshape(257, -1)                      # (257, channels)
    # A channel that does not scatter returns nothing at any angle: its ratio is 1, not 0/0
    # (double where, so that the gradient stays finite too).
    normal = table[-1]
    table = jnp.where(normal > 0, table / jnp.where(normal > 0, normal, 1.0), 1.0)

    def ratio(cos_incident):
        cos = jnp.clip(as_float_array(cos_incident), 0.0, 1.0)
        cos_b = cos.reshape(cos.shape + (1,) * n)
        inside = safe_sqrt(jnp.maximum(1 - (1 - cos_b**2) / jnp.square(eta), 0.0))   # S + C, Snell
        flat = jnp.broadcast_to(inside, cos.shape + jnp.shape(albedo)).reshape(cos.shape + (-1,))
        # On the uniform grid by arithmetic, not jnp.interp's search (a third of a 320 x 240
        # Lambert frame).
        position = flat * (len(grid) - 1)
        value = jnp.stack([interpolate_rows(position[..., c], table[:, c]) for c in range(table.shape[1])], -1)
        return value.reshape(cos.shape + jnp.shape(albedo))

    return ratio


def incidence_ratio(medium: Medium, cos_incident):
    r"""Total reflectance at incidence ``cos_incident`` (outside) over that at normal incidence,
    per channel: the factor by which oblique light returns more than the profiles' normal beam.

    ``cos_incident`` (shape ``S``) is refracted by ``medium.eta`` (shape ``C``) first; the
    result has shape ``S + C`` and is 1 at normal incidence. Uses the similarity albedo
    :math:`\sigma_s'/(\sigma_a + \sigma_s')`. Exact for isotropic scattering behind an
    index-matched boundary; behind a Fresnel boundary an upper bound (see the module notes).
    For many evaluations with one medium, :func:`incidence_law` solves once.

    With numbers (not tracers: no ``jit``, ``grad`` or ``vmap`` around it) the same steps run in
    NumPy, in the same dtype (``_incidence_ratio_numpy``; equal to 1e-13 in float64):
    op by op, JAX lowered some 40 small programs for them, 0.6 s of planning each new process.
    """
    if is_concrete((medium, cos_incident)):
        return device_array(np.asarray(_incidence_ratio_numpy(medium, cos_incident)))
    return incidence_law(medium)(cos_incident)


def _incidence_ratio_numpy(medium: Medium, cos_incident) -> np.ndarray:
    """:func:`incidence_law` ``(medium)(cos_incident)`` step by step in NumPy, in the dtype JAX
    would compute in (the same H iteration, grid and linear interpolation)."""
    sigma_a, sigma_s_prime, eta = (np.asarray(x) for x in (medium.sigma_a, medium.sigma_s_prime, medium.eta))
    albedo = sigma_s_prime / (sigma_a + sigma_s_prime)
    dtype = albedo.dtype
    # A Python number is weakly typed in JAX: it takes the medium's dtype, not float64.
    cos = np.asarray(cos_incident, dtype) if isinstance(cos_incident, (int, float)) else \
        np.asarray(as_float_array(cos_incident))
    n = albedo.ndim
    grid = np.linspace(0.0, 1.0, 257, dtype=dtype)
    h = h_function_numpy(albedo, grid)  # plane_albedo(albedo, grid) by h_function's steps
    table = (1.0 - h * np.sqrt(np.maximum(1 - albedo, 0.0))).reshape(257, -1)
    normal = table[-1]
    table = np.where(normal > 0, table / np.where(normal > 0, normal, 1.0), 1.0)  # as the JAX path
    # The law's ratio(cos): Snell, then interpolation per channel.
    cos = np.clip(cos, 0.0, 1.0)
    cos_b = cos.reshape(cos.shape + (1,) * n)
    inside = np.sqrt(np.maximum(1 - (1 - cos_b**2) / np.square(eta), 0.0))
    flat = np.broadcast_to(inside, cos.shape + albedo.shape).reshape(cos.shape + (-1,))
    value = np.stack([np.interp(flat[..., c], grid, table[:, c]) for c in range(table.shape[1])], -1)
    return value.reshape(cos.shape + albedo.shape).astype(np.result_type(dtype, cos.dtype), copy=False)


def deposit_depth(medium: Medium):
    r"""Depth [mm] at which the light that comes back out was, on average, first scattered:
    :math:`1 / (2\,\sigma_t'\,\eta)` per channel.

    A beam's first collisions are exponential in depth with mean :math:`1/\sigma_t'`; light
    that scatters once and leaves toward a normal view is weighted by
    :math:`e^{-\sigma_t' z (1 + 1/\mu_o)}`, mean :math:`1/(2\sigma_t')` at :math:`\mu_o = 1`.
    Behind a boundary rays bend toward the normal, and their spread at a depth is that of the
    apparent depth :math:`z/\eta` (paraxial). Used for point lights, whose rays keep spreading
    below the surface (:func:`jsss.render.lighting.depth_falloff`). Measured against Mitsuba on
    the index-matched ketchup plane under its point light 35 mm up (80 x 60 px, texture space,
    transport profile): within 8 mm of the lamp's foot jsss / Mitsuba was 1.109 / 1.022 / 1.014
    with the light read at the surface and 0.993 / 0.995 / 0.995 at this depth; the multiply
    scattered red (albedo' 0.75) follows the same rule as the single-scattered green and blue.
    """
    return 1.0 / (2.0 * (medium.sigma_a + medium.sigma_s_prime) * medium.eta)

def point_light_loss(distance, depth):
    r"""Share of a point light's irradiance that is lost between the surface and ``depth`` below
    it, on the axis under the lamp ``distance`` away: :math:`1 - (d / (d + z))^2` (inverse square
    law read at the apparent depth; both in mm). 0 for parallel light (``distance`` infinite)."""
    distance = jnp.asarray(distance)
    far = jnp.isinf(distance)
    safe = jnp.where(far, 1.0, distance)
    return jnp.where(far, 0.0, 1 - (safe / (safe + depth)) ** 2)


