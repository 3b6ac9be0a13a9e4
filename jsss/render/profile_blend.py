r"""A few basis profiles that span a parameter map's range, blended per texel.

Where :math:`\sigma_a` and :math:`\sigma_s'` vary over the surface, every point has its own
profile. Each channel's profile is a function of two numbers, its scale
:math:`x_1 = \ln\sigma_t'` and its shape :math:`x_2 = \ln(\sigma_a/\sigma_t') = \ln(1 - \alpha')`
(:math:`R(r) = \sigma_t'^2\,\tilde R(\sigma_t' r;\,\alpha')`), so a regular grid of nodes over
the map's range of :math:`(x_1, x_2)` per channel, each node a homogeneous medium with its own
Gaussian weights :math:`W_k` on the plan's shared variances, gives every texel's profile as
the bilinear blend

.. math:: R(r;\,y) \approx \sum_k a_k(y)\,\sum_i W_{k,i}\,G(v_i, r),

with :math:`a_k(y)` the bilinear weights of the texel's :math:`(x_1, x_2)` among the nodes.
The blend is linear in what the renderer blurs: texture space blurs :math:`a_k E` once per
node (:class:`~jsss.render.methods.TextureSpace`), which is Jensen's rule -- the parameters
at the entry point -- exactly for the blended profile. A two-material checker sits on the
corners of a 2 x 2 grid, where the blend is exact; between nodes its error is measured
(:attr:`ProfileBasis.error`, at the map's texels farthest from the nodes, against each one's
own fit) and the grid refined until it is at most the target.

**Light that crosses a sharp edge.** Jensen's rule carries the entry point's profile across
an edge unchanged: marble's long profile into the skin beside it (+40 % in blue at the first
millimetre of skin against a path tracer), and it ignores the light that marble loses into the
skin (+13 % on marble's side). The pair (entry medium :math:`k`, exit medium :math:`j`) gets
instead, for :math:`k \ne j`,

.. math:: K_{kj}(r) = \sqrt{R_k(r)\,R_j(r)} + s\,\rho_{jk}\,R_j(r),\qquad
          \rho_{jk} = \frac{\sqrt{D_j\sigma_{a,j}} - \sqrt{D_k\sigma_{a,k}}}
                           {\sqrt{D_j\sigma_{a,j}} + \sqrt{D_k\sigma_{a,k}}}:

the geometric mean is a path that runs half in each medium (it is reciprocal,
:math:`K_{kj} = K_{jk}` but for the image term), and :math:`\rho_{jk}` is diffusion's
reflection coefficient at an interface between two media (flux :math:`D\,\partial\phi/\partial n`
and fluence continuous, :math:`D = 1/(3\sigma_t')`): the exit medium's light mirrored at the
edge, negative where the other side absorbs more. For uniform light the mirror images of the
sources on the exit side are the sources across the edge, so the image term is the exit
medium's profile from the entry points across the edge. The image's strength :math:`s`
(:data:`IMAGE_STRENGTH`) is 1 for diffusion between two infinite media; below a surface,
light that crosses into the clearer medium mostly leaves through the surface there instead of
coming back, and against an independent two-media walk (``tests/truth/two_media_walk.py``,
marble beside skin1, uniform normal light, 0.5 mm bins) :math:`s` = 1 overshoots on both sides
of the edge in red (-13 / +14 % at the first bins). :math:`s` = 0.7 is the one constant
calibrated there (on two interfaces, index-matched and eta 1.3): the worst bin went from
Jensen's rule's 12 / 19 / 31 % and 13 / 34 / 88 % to 7 / 4 / 13 % and 8 / 7 / 12 % (blue's
worst is the first 0.5 mm of skin, where the geometric mean's core is too small, whatever
:math:`s`). Mitsuba's checker plane, a different truth and geometry (a point lamp), checks it
(``benchmarks/textured_truth.py``).

The rule applies where the entry and exit media differ, not where a texel is a blend of
nodes: with :math:`a_k(y)` the entry point's blend weights and :math:`b_j(x)` the exit point's,

.. math:: M(x) = \sum_k [R_k * (a_k E)](x)
          + \sum_{j,k} b_j(x) \left[C_{kj} * \big((a_k - b_k(x)) E\big)\right](x),
          \qquad C_{kj} = K_{kj} - R_k,

which is Jensen's rule wherever :math:`a = b` (a smooth map changes only at second order)
and the pair rule exactly across a sharp two-media edge. On shared variances
:math:`C_{kj} = \sum_i U_{kj,i} G_i`; since :math:`\sum_k a_k = 1`, the blur of :math:`E`
is the sum of the blurs of :math:`a_k E`, so the correction costs no blur.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ..medium import Medium
from .profiles import _numpy_fit, _reference, full_profile, profile_radii, shared_variances
from .scene import Material
from .surface_maps import blend_coefficients, coordinates

__all__ = ["ProfileBasis", "choose_basis"]

MAX_NODES = 16  # basis profiles at most (each is one more blur chain in texture space)
IMAGE_STRENGTH = 0.7  # s: the edge's mirror image of the exit medium's light (module notes), calibrated on a walk


@dataclass(frozen=True, eq=False)
class ProfileBasis:
    """Nodes and their Gaussian weights (NumPy), fixed for a plan.

    Attributes
    ----------
    scale_nodes : (N1, C) ln sigma_t' per channel; shape_nodes : (N2, C) ln(sigma_a / sigma_t')
    weights : (N1 * N2, n, C) each node's Gaussian weights on the plan's variances (node k =
        i * N2 + j)
    variances : (n,) [mm^2]
    error : float, the blend's worst relative RMS profile error at the map's texels
    fit_error : float, the worst node's own Gaussian-fit error
    crossing : (K, K, n, C) the weights :math:`U_{kj}` of :math:`C_{kj} = K_{kj} - R_k` for
        light entering node ``k``'s medium and leaving node ``j``'s (zero where k = j)
    """

    scale_nodes: np.ndarray
    shape_nodes: np.ndarray
    weights: np.ndarray
    variances: np.ndarray
    error: float
    fit_error: float
    crossing: np.ndarray

    @property
    def size(self) -> int:
        return self.weights.shape[0]

    def media(self, eta) -> Medium:
        """The nodes as one Medium of shape (K, C)."""
        return _node_medium(self.scale_nodes, self.shape_nodes, eta)

    def describe(self) -> str:
        n1, n2 = len(self.scale_nodes), len(self.shape_nodes)
        crossing = "; light that changes medium by the edge rule" if self.size > 1 else ""
        return (f"{n1} x {n2} basis profiles, blending error {100 * self.error:.2f} % "
                f"(worst node's fit {100 * self.fit_error:.2f} %){crossing}")


def _node_medium(scale_nodes, shape_nodes, eta) -> Medium:
    sigma_t = np.exp(scale_nodes)[:, None, :]  # (N1, 1, C)
    ratio = np.exp(shape_nodes)[None, :, :]  # (1, N2, C)
    sigma_a = (sigma_t * ratio).reshape(-1, scale_nodes.shape[-1])
    sigma_s = (sigma_t * (1 - ratio)).reshape(-1, scale_nodes.shape[-1])
    return Medium(sigma_a, sigma_s, np.broadcast_to(np.asarray(eta, float), sigma_a.shape))


def _axis(lo, hi, n):
    """(n, C) regular nodes per channel from lo to hi (one node where a channel does not vary)."""
    return np.linspace(lo, hi, n) if n > 1 else ((lo + hi) / 2)[None]


def _references(material: Material, media: Medium, r):
    """Exact profiles (K, N, C) and totals (K, C) of each node medium."""
    K = media.sigma_a.shape[0]
    out = [_reference(material, jnp.asarray(r), Medium(media.sigma_a[k], media.sigma_s_prime[k], media.eta[k]))
           for k in range(K)]
    return np.stack([np.asarray(p, float) for p, _ in out]), np.stack([np.asarray(t, float) for _, t in out])


def _interface_reflection(media: Medium) -> np.ndarray:
    """(K, K, C) diffusion's reflection coefficient rho[j, k] of medium j's light at an
    interface with medium k: (q_j - q_k) / (q_j + q_k) with q = sqrt(D sigma_a) =
    sqrt(sigma_a / (3 sigma_t')); 0 between two media that absorb nothing."""
    sigma_a = np.asarray(media.sigma_a, float)
    q = np.sqrt(sigma_a / (3 * (sigma_a + np.asarray(media.sigma_s_prime, float))))
    num, den = q[:, None] - q[None, :], q[:, None] + q[None, :]
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def _crossing_weights(variances, r, media: Medium, profiles, weights) -> np.ndarray:
    """(K, K, n, C) weights U[k, j] of C_kj = sqrt(R_k R_j) + s rho_jk R_j - R_k (the module
    notes) on ``variances``: the geometric mean fitted as any profile, the rest from the
    nodes' own weights ``weights`` (K, n, C)."""
    K = weights.shape[0]
    crossing = np.zeros((K,) + weights.shape)
    rho = _interface_reflection(media)
    for k in range(K):
        for j in range(K):
            if j == k:
                continue
            mean = np.sqrt(profiles[k] * profiles[j])  # (N, C)
            total = 2 * np.pi * np.trapezoid(r[:, None] * mean, r, axis=0)
            fitted, _ = _numpy_fit(variances, r, (mean, total))
            crossing[k, j] = fitted + IMAGE_STRENGTH * rho[j, k] * weights[j] - weights[k]
    return crossing


def _fits(variances, r, profiles, totals):
    fitted = [_numpy_fit(variances, r, (p, t)) for p, t in zip(profiles, totals)]
    return np.stack([w for w, _ in fitted]), float(max(np.max(e) for _, e in fitted))


def _corner_profiles(material: Material, corners: Medium):
    """Each corner node's whole Gaussian-sum profile (what the homogeneous plan fits against)."""
    return [full_profile(material, Medium(corners.sigma_a[k], corners.sigma_s_prime[k], corners.eta[k]))
            for k in range(corners.sigma_a.shape[0])]


def _basis_radii(fulls, variances) -> np.ndarray:
    """Radii [mm] for the nodes' fits and errors: the corners' own (the homogeneous plan's
    ``profile_radii``), so that a node's fit error reads as the same material's homogeneous profile
    error, reaching down to a third of the narrowest variance's sigma (a narrower range leaves
    that Gaussian's weight free where no radius sees it, and the blend of two such fits is then
    off by more than either fit). A transport profile's near-source peak makes the relative
    RMS grow as the radii reach deeper, so the range must not follow the variances below that."""
    own = [profile_radii(f) for f in fulls]
    lo = min(min(r[0] for r in own), np.sqrt(np.min(variances)) / 3)
    hi = max(max(r[-1] for r in own), np.sqrt(np.max(variances)) * 8)
    return np.geomspace(lo, hi, 800)


def _variances_for(material: Material, corners: Medium, fulls, target: float, max_terms: int = 12):
    """The fewest shared variances on which every corner node's profile (``fulls``) is fitted within ``target``."""
    spans = [shared_variances(f, 2) for f in fulls]
    lo, hi = min(s[0] for s in spans), max(s[-1] for s in spans)
    r = np.geomspace(np.sqrt(lo) / 30, np.sqrt(hi) * 8, 800)
    profiles, totals = _references(material, corners, r)
    best = None
    for n in range(1, max_terms + 1):
        candidates = [np.geomspace(lo, hi, n)] if n == 1 else [np.geomspace(lo * f, hi, n) for f in (1.0, 0.1, 0.01)]
        for grid in candidates:
            _, error = _fits(grid, r, profiles, totals)
            if np.isfinite(error) and (best is None or error < best[1]):
                best = (grid, error)
        if best[1] <= target:
            break
    return best[0], r


def choose_basis(material: Material, sigma_a, sigma_s, target: float, *, variances=None) -> ProfileBasis:
    """The coarsest node grid over the maps' range whose blend is within ``target`` (relative RMS).

    ``sigma_a``, ``sigma_s`` (..., C) [1/mm] are the maps' values (all texels); ``variances``
    (default: the fewest that fit every corner node within ``target``) are the plan's.
    """
    x1, x2 = coordinates(np.asarray(sigma_a, float).reshape(-1, 3), np.asarray(sigma_s, float).reshape(-1, 3))
    points = np.unique(np.round(np.concatenate([x1, x2], 1), 9), axis=0)  # the texels' distinct media
    points = (points[:, :3], points[:, 3:])
    lo1, hi1, lo2, hi2 = x1.min(0), x1.max(0), x2.min(0), x2.max(0)
    varies1 = bool(np.any(hi1 - lo1 > 1e-9))
    varies2 = bool(np.any(hi2 - lo2 > 1e-9))
    eta = np.broadcast_to(np.asarray(material.eta, float), (3,))
    corners = _node_medium(_axis(lo1, hi1, 2 if varies1 else 1), _axis(lo2, hi2, 2 if varies2 else 1), eta)
    fulls = _corner_profiles(material, corners)
    if variances is None:
        variances, _ = _variances_for(material, corners, fulls, target)
    variances = np.asarray(variances, float)
    r = _basis_radii(fulls, variances)
    n1, n2 = (2 if varies1 else 1), (2 if varies2 else 1)
    while True:
        scale_nodes, shape_nodes = _axis(lo1, hi1, n1), _axis(lo2, hi2, n2)
        media = _node_medium(scale_nodes, shape_nodes, eta)
        profiles, totals = _references(material, media, r)
        weights, fit_error = _fits(variances, r, profiles, totals)
        error = _blend_error(material, variances, r, scale_nodes, shape_nodes, weights, eta, points)

        def basis():
            crossing = _crossing_weights(variances, r, media, profiles, weights)
            return ProfileBasis(scale_nodes, shape_nodes, weights, np.asarray(variances), error, fit_error, crossing)

        if error <= target:
            return basis()
        trials = []
        for m1, m2 in ((n1 + 1, n2), (n1, n2 + 1)):
            if (m1 > n1 and not varies1) or (m2 > n2 and not varies2) or m1 * m2 > MAX_NODES:
                continue
            s1, s2 = _axis(lo1, hi1, m1), _axis(lo2, hi2, m2)
            w, _ = _fits(variances, r, *_references(material, _node_medium(s1, s2, eta), r))
            trials.append((_blend_error(material, variances, r, s1, s2, w, eta, points), m1, m2))
        if not trials:  # as many nodes as allowed: the plan says the target was not reached
            return basis()
        # Refine the axis whose extra node helps more.
        _, n1, n2 = min(trials)


def _worst_points(x1, x2, scale_nodes, shape_nodes, count: int = 24):
    """The map's texels (as (x_1, x_2) per channel) farthest from the nodes: where the blend errs most."""
    score = 0.0
    for x, nodes in ((x1, scale_nodes), (x2, shape_nodes)):
        n = len(nodes)
        if n > 1:
            step = np.where(np.abs(nodes[1] - nodes[0]) > 0, nodes[1] - nodes[0], 1.0)
            t = np.clip((x - nodes[0]) / step, 0, n - 1)
            score = score + np.minimum(t - np.floor(t), np.ceil(t) - t).sum(-1)
    order = np.argsort(score)[::-1][:count] if np.ndim(score) else np.arange(min(count, len(x1)))
    return x1[order], x2[order]


def _blend_error(material, variances, r, scale_nodes, shape_nodes, weights, eta, points) -> float:
    """Worst relative RMS difference, over the texels ``points`` ((x_1, x_2), each (P, C)) and
    channels, between the blended profile and that texel's own fit on the same variances, over
    its exact profile's norm (d'Eon's measure, eq. 10): what the blending adds to the fit's own
    error."""
    if len(scale_nodes) == 1 and len(shape_nodes) == 1:
        return 0.0
    x1, x2 = _worst_points(*points, scale_nodes, shape_nodes)
    sigma_t, ratio = np.exp(x1), np.exp(x2)
    centres = Medium(sigma_t * ratio, sigma_t * (1 - ratio), np.broadcast_to(eta, x1.shape))
    profiles, totals = _references(material, centres, r)  # (M, N, C)
    own, _ = _fits(variances, r, profiles, totals)  # each texel's own fit (M, n, C)
    a = blend_coefficients(scale_nodes, shape_nodes, centres.sigma_a, centres.sigma_s_prime, xp=np)  # (M, K, C)
    blended = np.einsum("mkc,knc->mnc", a, weights)
    basis = np.exp(-r[:, None] ** 2 / (2 * variances)) / (2 * np.pi * variances)  # (N, n)
    difference = np.einsum("ri,mic->mrc", basis, blended - own)
    num = np.trapezoid(r[None, :, None] * difference**2, r, axis=1)
    den = np.trapezoid(r[None, :, None] * profiles**2, r, axis=1)
    return float(np.sqrt(np.max(num / den)))
