r"""From a scene's material to the few shared-variance Gaussians the blurs use.

The renderer blurs one texture per variance and weights it per colour channel, so every
channel must use the *same* variances (d'Eon 2007 sec. 5). The full profile -- the
closed-form 8-Gaussian dipole fit per channel, the polynomial-of-Gaussians stack of a
layered material, or a GaussianSum given in the scene -- fixes the range; the weights on
``n`` geometrically spaced variances in that range are fitted to the *exact* profile
(dipole, Hankel-space layer stack) by constrained linear least squares, which keeps each
channel's total. How large ``n`` must be is measured per material against the exact
profile (:func:`choose_variances`), not assumed.
"""

from __future__ import annotations

import collections
import functools
import hashlib
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .. import transport
from ..diffusion import dipole
from .. import layers as _layers
from ..gaussians import GaussianSum, empirical_dipole_fit, evaluate, layers_as_gaussians, to_gaussian_sum
from ..numerics import device_array, is_concrete
from ..stored_programs import reusable_program
from .kept import save_arrays
from .scene import Material

__all__ = ["choose_variances", "exact_profile", "full_profile", "keep_profiles_in", "profile_radii", "reduction_error",
           "render_profile", "shared_variances"]


def full_profile(material: Material, medium=None) -> GaussianSum:
    """The material's whole Gaussian-sum profile, weights (n, 3).

    ``medium`` replaces the scene's homogeneous medium (to differentiate with respect to it).
    """
    if material.gaussians is not None:
        return material.gaussians
    if material.layers:
        return _layered_profile(material)
    gs = empirical_dipole_fit(material.medium if medium is None else medium)
    return GaussianSum(gs.weights.reshape(gs.weights.shape[0], -1), gs.variances)


_LAYERED_KEPT = 8  # stacks (profiles and references together) remembered by _remembered
_layered_profiles: collections.OrderedDict = collections.OrderedDict()
# Where stacks' profiles are also kept on disk: None (the library's default) keeps them in memory
# only; console scripts name a folder with keep_profiles_in.
_profiles_dir: Path | None = None


def keep_profiles_in(folder) -> None:
    """Keep layered stacks' profiles under ``folder/profiles/`` from now on (console scripts; None:
    memory only). A skin preset's profile is 7-10 s of multipole fits, Hankel matrices and
    polynomial products on a 2-core CPU; read back, a few milliseconds."""
    global _profiles_dir
    _profiles_dir = None if folder is None else Path(folder)


@functools.lru_cache(maxsize=1)
def _code_digest() -> str:
    """A digest of the code the kept profiles come from (jsss.layers, jsss.gaussians, this
    module): a change to any of it makes every file kept before it a miss, not a stale answer."""
    from .. import gaussians, layers

    digest = hashlib.sha256()
    for package in (layers, gaussians):
        for source in sorted(Path(package.__file__).parent.glob("*.py")):
            digest.update(source.read_bytes())
    digest.update(Path(__file__).read_bytes())
    return digest.hexdigest()[:16]


def _remembered(kind: str, stack, extra: tuple, compute, build=lambda *arrays: arrays):
    """``build(*compute())`` (``compute`` returns a tuple of arrays) for a stack's numbers, one
    object per stack: kept for the process (the last
    ``_LAYERED_KEPT``) and, where :func:`keep_profiles_in` named a folder, on disk as
    ``profiles/<kind>-<digest>.npz``, written atomically (an unreadable file is recomputed and
    replaced). Traced stacks (under jit or grad) are never kept."""
    if not is_concrete(stack):
        return build(*compute())
    leaves, treedef = jax.tree_util.tree_flatten(stack)
    arrays = [np.asarray(leaf) for leaf in leaves] + [np.asarray(a) for a in extra]
    key = (kind, str(treedef), jax.config.jax_enable_x64, tuple((a.dtype.str, a.shape, a.tobytes()) for a in arrays))
    if key in _layered_profiles:
        _layered_profiles.move_to_end(key)
        return _layered_profiles[key]
    path = None
    if _profiles_dir is not None:
        name = hashlib.sha256(repr(key).encode() + _code_digest().encode()).hexdigest()[:32]
        path = _profiles_dir / "profiles" / f"{kind}-{name}.npz"
    value = None
    if path is not None and path.is_file():
        try:
            with np.load(path) as kept:
                value = tuple(kept[f"a{i}"] for i in range(len(kept.files)))
        except (OSError, ValueError, KeyError, EOFError) as error:
            warnings.warn(f"{path}: unreadable kept profile ({error}); computing it again", stacklevel=3)
    if value is None:
        value = tuple(np.asarray(a) for a in compute())
        if path is not None:
            _write_atomically(path, value)
    _layered_profiles[key] = value = build(*value)
    while len(_layered_profiles) > _LAYERED_KEPT:
        _layered_profiles.popitem(last=False)
    return value


def _write_atomically(path: Path, arrays: tuple) -> None:
    try:
        save_arrays(path, {f"a{i}": a for i, a in enumerate(arrays)})
    except OSError as error:  # a read-only cache folder must not stop a render
        warnings.warn(f"{path}: cannot keep the profile there ({error})", stacklevel=4)


def _layered_profile(material: Material) -> GaussianSum:
    """The stack's Kubelka-Munk profile, remembered by the stack's numbers (:func:`_remembered`).

    Planning asks for it three times (the frame's features, the variances, the render's
    weights), and each is 2-3 s of multipole fits and polynomial products on a CPU; the
    stack does not change between them.
    """
    stack = (tuple(material.layers), material.base)

    def compute():
        gs = to_gaussian_sum(layers_as_gaussians(list(material.layers), material.base)[0])
        return gs.weights, gs.variances

    return _remembered("sum", stack, (), compute, GaussianSum)


def exact_profile(material: Material, r) -> np.ndarray:
    """The reference :math:`R(r)` [1/mm^2], shape (N, 3): the medium's profile model (dipole or
    transport), the multilayer stack, or the given sum."""
    r = jnp.asarray(r)
    if material.gaussians is not None:
        return np.asarray(evaluate(material.gaussians, r))
    if material.layers:
        return np.asarray(_layers.stack(list(material.layers), material.base, r=r).R)
    return np.asarray(_medium_profile(material, material.medium, r)[0])


def _medium_profile(material: Material, medium, r):
    """Profile (N, 3) and total (3,) of a homogeneous medium under the material's profile model."""
    if material.profile_model == "transport" and is_concrete(medium):
        transport.check_medium(medium, g=material.g)  # the jitted program below cannot raise
    return _model_profile(medium, r, model=material.profile_model, g=float(material.g))


@reusable_program(static_argnames=("model", "g"))
@functools.partial(jax.jit, static_argnames=("model", "g"))
def _model_profile(medium, r, *, model: str, g: float):
    """One program per model: the transport profile op by op was 250 small programs and 2.8 s of
    a command's start (the planner's variances), and is kept traced across processes."""
    if model == "transport":
        return transport.profile(medium, r, g=g), transport.total_reflectance(medium, g=g)
    return dipole.profile(medium, r), dipole.total_reflectance(medium)


def shared_variances(full: GaussianSum, n: int, *, significant: float = 1e-3) -> np.ndarray:
    """``n`` geometrically spaced variances spanning the terms that carry weight.

    A term counts when its weight is at least ``significant`` of its channel's total;
    ``n = 1`` gives the geometric mean of the channels' mean variances.
    """
    w = np.abs(np.asarray(full.weights))
    v = np.asarray(full.variances)
    keep = (w >= significant * w.sum(0, keepdims=True)).any(1) & (v > 0)
    lo, hi = v[keep].min(), v[keep].max()
    if n == 1 or hi <= lo * (1 + 1e-9):
        mean = (w * v[:, None]).sum(0) / np.maximum(w.sum(0), 1e-300)
        return np.array([float(np.exp(np.mean(np.log(mean[mean > 0]))))])
    return np.geomspace(lo, hi, n)


def profile_radii(full: GaussianSum) -> np.ndarray:
    """Log-spaced radii [mm] that resolve the narrowest term's core and the widest term's tail."""
    v = np.asarray(full.variances)
    v = v[v > 0]
    return np.geomspace(np.sqrt(v.min()) / 30, np.sqrt(v.max()) * 8, 600)


def _reference(material: Material, r, medium=None):
    """Exact profile (N, 3) and total (3,) at radii ``r``; differentiable in ``medium``."""
    if material.medium is not None or medium is not None:
        return _medium_profile(material, material.medium if medium is None else medium, r)
    if material.gaussians is not None:
        profile = jnp.asarray(exact_profile(material, r), r.dtype)
        return profile, jnp.asarray(material.gaussians.weights, r.dtype).sum(0)
    # The stack's own total (its spectrum at k = 0), not a quadrature of R(r) over the fit's
    # radii: a weakly absorbing stack has a 1/r^3 tail, and cutting it at the widest
    # Gaussian's 8 sigma lost 1-2 % of a non-absorbing stack's light (the furnace test).
    def compute():
        stacked = _layers.stack(list(material.layers), material.base, r=r)
        return stacked.R, stacked.R_total

    profile, total = _remembered("stack", (tuple(material.layers), material.base), (r,), compute)
    return jnp.asarray(profile, r.dtype), jnp.asarray(total, r.dtype)


def _fit_weights(variances, r, profile, total, xp=jnp):
    """Constrained least squares: min int r (R - sum w G)^2 dr subject to sum w = total.

    ``xp`` is ``jax.numpy`` (differentiable) or ``numpy`` (the planner's search, which
    would otherwise compile once per trial size).
    """
    v = xp.asarray(variances, dtype=r.dtype)
    basis = xp.exp(-r[:, None] ** 2 / (2 * v[None, :])) / (2 * np.pi * v[None, :])  # (N, n)
    wr = r * xp.gradient(r)  # quadrature weights of the r dr integral
    A = (basis * wr[:, None]).T @ basis
    b = (basis * wr[:, None]).T @ profile
    n = v.shape[0]
    scale = xp.max(xp.abs(xp.diag(A)))  # keeps the KKT system well scaled
    kkt = xp.block([[A / scale, xp.ones((n, 1))], [xp.ones((1, n)), xp.zeros((1, 1))]])
    rhs = xp.concatenate([b / scale, xp.reshape(total, (1, -1))])
    weights = xp.linalg.solve(kkt, rhs)[:n]
    return weights, v, basis


def render_profile(material: Material, variances, *, radii=None, medium=None) -> GaussianSum:
    r"""Weights on the given ``variances`` that best match the exact profile, per channel.

    Minimises d'Eon's power error :math:`\int r\,(R - \sum_i w_i G_i)^2\,dr` subject to
    :math:`\sum_i w_i = \int R\,dA` (the total diffuse reflectance is kept exactly), a
    linear least-squares problem solved in closed form, so the weights are differentiable
    in ``medium`` (which replaces the scene's homogeneous medium).

    Returns
    -------
    GaussianSum with weights (n, 3).
    """
    r = device_array(np.asarray(profile_radii(full_profile(material)))) if radii is None else jnp.asarray(radii)
    profile, total = _reference(material, r, medium)
    if is_concrete((variances, profile, total)):
        # NumPy's solve: the jitted one calls LAPACK, whose kernels jaxlib loads by importing
        # SciPy's (0.25 s of a command's start, where the frame itself calls none). A singular
        # system (equal variances) falls through to JAX's, which answers NaN as it always did.
        try:
            weights, v, _ = _fit_weights(np.asarray(variances, r.dtype), np.asarray(r), np.asarray(profile),
                                         np.asarray(total), xp=np)
            return GaussianSum(device_array(weights), device_array(v))
        except np.linalg.LinAlgError:
            pass
    weights, v, _ = _fit_weights_jitted(variances, r, profile, total)
    return GaussianSum(weights, v)


# One program, not 20 operations each compiled (1.8 s per render), kept traced across processes.
_fit_weights_jitted = reusable_program()(jax.jit(_fit_weights))


def _numpy_fit(variances, r, reference, resolution: float = 0.0):
    """Weights on ``variances`` and their per-channel relative RMS error, in NumPy float64.

    The error (d'Eon's eq. 10) is measured from half the ``resolution`` [mm] (a pixel's
    footprint) out. Why: the transport profile's single-scattering core rises like 1/r at the
    source, and eq. 10's weight :math:`r R^2` makes that core's share of the error grow without
    bound as the radii shrink (ketchup: 34 % with 12 Gaussians, while the flux they misplace
    beyond a pixel is 0.3-2.2 %). Inside one pixel the camera sees only the core's flux, which
    the fit keeps exactly (its weights sum to the total). The fit itself uses every radius.
    """
    profile, total = (np.asarray(a, float) for a in reference)
    weights, _, basis = _fit_weights(variances, r, profile, total, xp=np)
    seen = r >= resolution / 2
    if np.count_nonzero(seen) < 2:
        seen = np.ones_like(r, bool)
    r, profile, residual = r[seen], profile[seen], (profile - basis @ weights)[seen]
    num = np.trapezoid(r[:, None] * residual**2, r, axis=0)
    den = np.trapezoid(r[:, None] * profile**2, r, axis=0)
    # A channel that returns no light (a clear drink's sigma_s' = 0) has nothing to miss: error 0, not 0/0.
    return weights, np.sqrt(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0))


def reduction_error(material: Material, variances, *, radii=None, reference=None, resolution: float = 0.0) -> np.ndarray:
    """d'Eon's relative RMS error (eq. 10) of the render profile against the exact one, per channel.

    ``radii`` and ``reference`` (a pair: the exact profile there and its total) may be
    passed to reuse them. The error is measured from half the ``resolution`` [mm] out
    (:func:`_numpy_fit`). Computed in NumPy float64.
    """
    r = np.asarray(profile_radii(full_profile(material)) if radii is None else radii, float)
    reference = _reference(material, jnp.asarray(r)) if reference is None else reference
    return _numpy_fit(variances, r, reference, resolution)[1]


def choose_variances(material: Material, target: float, *, max_terms: int = 12, resolution: float = 0.0):
    """The fewest shared variances whose profile error is at most ``target``, measured from half
    the ``resolution`` [mm] (the pixel footprint) out (:func:`_numpy_fit`).

    A material given as Gaussians keeps its own variances. Otherwise tries
    ``n = 1 .. max_terms`` geometric grids whose narrow end is the narrowest significant
    term, or 10 or 100 times narrower (layered materials have sharp cores).

    Returns
    -------
    profile : GaussianSum
        The render profile on the chosen variances (weights (n, 3), NumPy float64), as
        :func:`render_profile` would fit it.
    error : float (worst channel); reached : bool
    """
    full = full_profile(material)
    r = profile_radii(full)
    reference = tuple(np.asarray(a, float) for a in _reference(material, device_array(r)))
    if material.gaussians is not None:  # the profile is given: use its own variances
        grid = np.asarray(full.variances)
        weights, _ = _numpy_fit(grid, r, reference)
        return GaussianSum(weights, grid), 0.0, True
    best = None
    for n in range(1, max_terms + 1):
        base = shared_variances(full, n)
        grids = [base] if n == 1 else [np.geomspace(base[0] * f, base[-1], n) for f in (1.0, 0.1, 0.01)]
        for grid in grids:
            weights, errors = _numpy_fit(grid, r, reference, resolution)
            error = float(np.max(errors))
            if np.isfinite(error) and (best is None or error < best[2]):
                best = (grid, weights, error)
        if best[2] <= target:
            return GaussianSum(best[1], best[0]), best[2], True
    return GaussianSum(best[1], best[0]), best[2], False
