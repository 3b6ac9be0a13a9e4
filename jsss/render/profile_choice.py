"""Which profile model a homogeneous medium renders with, and how far each is from transport.

A homogeneous medium's profile comes from the dipole (Jensen 2001, sec. 2.4; diffusion) or
from :mod:`jsss.transport` (scaled Monte Carlo tables, exact to radiative transfer within
their noise). Measured against a path tracer (``docs/benchmarks/transport_truth.md``), the
dipole's frames carry its error in the total diffuse reflectance: ketchup +9 / +15 / +13 %
(R / G / B), marble about -1 %. So each model's **predicted error** is the relative
difference of its total :math:`R_d` from the transport truth's, per channel:

* the dipole: :math:`R_d^{dip} / R_d^{tr} - 1` (both per unit entering flux, the medium's
  ``eta`` and ``g``);
* the transport tables: their own Monte Carlo standard error of the total
  (``error_total`` over ``total``, :func:`jsss.transport.table_info`).

This is the error of a frame whose light varies slowly across the profile's width. Near a
sharp light edge the profiles' shapes differ too (the dipole misplaces 14-20 % of a
high-albedo medium's light within a transport length of the source, and more at low albedo;
``tests/jsss/render/test_profile_choice.py`` measures it), and the transport profile is the
right shape there as well.

``profile = "auto"`` (the default of a scene's homogeneous medium) is the planner's rule
for every pass: the cheaper model wherever it meets its share of the accuracy target. The
dipole, whose closed-form Gaussian fit needs fewer terms and no tables, is kept where its
predicted error is at most a quarter of the target (marble: -0.9 to -1.2 %, within a quarter of
5 %); otherwise the transport tables (ketchup, skin1 at 5 %). Where the tables do not cover
the medium (eta outside 1.0-1.6, an untabulated ``g``, reduced albedo below 0.001, sigma_s' = 0)
the dipole is used and the plan says why. An explicit ``profile`` is obeyed, and its predicted
error is stated. A material with parameter maps keeps the dipole only where every texel's
medium would (:func:`map_media`: the checker plane's marble base alone is -1 %, its absorbing
squares +3 / +17 / +23 %, so it takes the tables).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .. import transport
from ..diffusion import dipole
from ..medium import Medium
from ..stored_programs import reusable_program
from .surface_maps import ARTIST_KEYS

__all__ = ["MODELS", "ProfileChoice", "choose_profile", "map_media", "predicted_errors"]

MODELS = ("auto", "dipole", "transport")


@dataclass(frozen=True, eq=False)
class ProfileChoice:
    """The profile model a homogeneous medium renders with, and why.

    Attributes
    ----------
    model : {"dipole", "transport"}, the model used
    requested : {"auto", "dipole", "transport"}, what the scene or caller asked for
    why : str, one line for ``--plan``
    target : float, the accuracy target (relative) an ``auto`` choice was made for
    dipole_error, transport_error : ndarray (3,) or None, each model's predicted relative
        error of the total diffuse reflectance against the transport truth (signed for the
        dipole; the tables' standard error for transport); None where the tables do not
        cover the medium
    """

    model: str
    requested: str
    why: str
    target: float = 0.05
    dipole_error: np.ndarray | None = None
    transport_error: np.ndarray | None = None

    def __post_init__(self):
        if self.model not in MODELS[1:]:
            raise ValueError(f"profile model must be 'dipole' or 'transport'; got {self.model!r}.")
        if self.requested not in MODELS:
            raise ValueError(f"requested profile must be one of {', '.join(MODELS)}; got {self.requested!r}.")

    @property
    def predicted_error(self) -> float | None:
        """The chosen model's predicted error (worst channel, relative), or None where unknown."""
        errors = self.dipole_error if self.model == "dipole" else self.transport_error
        return None if errors is None else float(np.max(np.abs(errors)))

    def describe(self) -> str:
        return f"profile: {self.model} -- {self.why}"


def _channels(values) -> str:
    return " / ".join(f"{100 * v:+.1f}" for v in np.asarray(values, float))


def _table_error(medium: Medium, g: float) -> np.ndarray:
    """Relative standard error of the transport tables' total at ``medium`` (nearest eta and
    absorption nodes; NumPy)."""
    from ..transport.profiles import (
        _tables,  # the totals sit beside their errors in one file
    )

    data = _tables()
    ig = int(np.argmin(np.abs(data["gs"] - g)))
    ratio = np.asarray(medium.sigma_a, float) / np.asarray(medium.sigma_s_prime, float)  # (3,) or (n, 3)
    eta = np.broadcast_to(np.asarray(medium.eta, float), ratio.shape)
    ie = np.argmin(np.abs(data["etas"] - eta[..., None]), axis=-1)
    ia = np.argmin(np.abs(np.log(np.maximum(data["absorption"], 1e-300)) - np.log(np.maximum(ratio, 1e-300))[..., None]),
                   axis=-1)
    return data["error_total"][ie, ig, ia] / data["total"][ie, ig, ia]


def predicted_errors(medium: Medium, *, g: float = 0.0):
    """``(dipole_error, transport_error, reason)``: each model's predicted relative error of the
    total against the transport truth, per channel (:class:`ProfileChoice`), or ``(None, None,
    reason)`` where the tables do not cover ``medium`` (``reason`` names what is out of range)."""
    try:
        transport.check_supported(medium.eta, g)
        transport.check_medium(medium, g=g)
    except ValueError as error:
        return None, None, str(error)
    exact, diffusion = (np.asarray(a, float) for a in _totals(medium, g=float(g)))
    return diffusion / exact - 1.0, _table_error(medium, g), ""


@reusable_program(static_argnames=("g",))
@functools.partial(jax.jit, static_argnames="g")
def _totals(medium: Medium, *, g: float):
    """Both models' R_d in one program: every scene load asks for them, and tracing the two
    separately cost a cold start 0.3 s more."""
    return transport.total_reflectance(medium, g=g), dipole.total_reflectance(medium)


MAP_QUANTILES = (0.0, 0.01, 0.5, 0.99, 1.0)  # of a parameter map's reduced albedo, per channel


def map_media(maps, eta) -> Medium | None:
    """Media spanning a parameter map's reduced albedos, or None for no parameter map.

    Coefficient maps only: an artist's maps (diffuse reflectance, mean free path) were turned into
    coefficients with the model chosen for the base medium, and keep it. A model's R_d error
    against the transport truth depends on the reduced albedo and eta
    alone (both models' totals are scale-free), so the map's spread is its albedos' quantiles
    :data:`MAP_QUANTILES` per channel: a ``(5, 3)`` medium at sigma_s' = 1 [1/mm] (where a
    texel has no scattering, its albedo is 0 and the tables do not cover it).
    """
    if maps is None or maps.sigma_a is None or any(key in ARTIST_KEYS for key, _ in maps.files):
        return None  # (an artist's maps were converted to coefficients with the model chosen for the base)
    sigma_a, sigma_s = maps.sigma_a.reshape(-1, 3), maps.sigma_s_prime.reshape(-1, 3)
    albedo = np.quantile(sigma_s / (sigma_a + sigma_s), MAP_QUANTILES, axis=0)
    absorption = np.where(albedo > 0, (1 - albedo) / np.maximum(albedo, 1e-300), np.inf)
    return Medium(jnp.asarray(np.minimum(absorption, 1e300)), jnp.asarray(np.where(albedo > 0, 1.0, 0.0)),
                  jnp.asarray(np.broadcast_to(np.asarray(eta, float), (3,))))


def _over_map(choice: ProfileChoice, texels: Medium, g: float) -> ProfileChoice:
    """An ``auto`` dipole choice checked over a parameter map's texels: where some texel's dipole
    error exceeds a quarter of the target, the tables (or, where they do not cover that texel,
    the dipole with the reason)."""
    dipole_error, transport_error, reason = predicted_errors(texels, g=g)
    albedo = np.asarray(texels.sigma_s_prime / (texels.sigma_a + texels.sigma_s_prime))
    spread = " / ".join(f"{a.min():.3g}-{a.max():.3g}" for a in albedo.T)
    if dipole_error is None:
        return dataclasses.replace(choice, why=choice.why + f"; the parameter map's texels (reduced albedo {spread}, "
                                                            f"R / G / B) reach beyond the tables ({reason})")
    worst = float(np.max(np.abs(dipole_error)))
    share = choice.target / 4
    if worst <= share:
        return dataclasses.replace(choice, why=choice.why + f"; over the parameter map (reduced albedo {spread}) "
                                                            f"within {100 * worst:.2g} %")
    why = (f"auto: over the parameter map's texels (reduced albedo {spread}, R / G / B) the dipole's R_d is up to "
           f"{100 * worst:.2g} % off the transport truth's, > a quarter of the target ({100 * share:.2g} %); the "
           f"tables' own error {100 * np.max(transport_error):.2g} %")
    return ProfileChoice("transport", "auto", why, choice.target, choice.dipole_error, choice.transport_error)


def choose_profile(medium: Medium, *, g: float = 0.0, requested: str = "auto", target: float = 0.05,
                   texels: Medium | None = None) -> ProfileChoice:
    """The profile model for ``medium`` (concrete arrays; Henyey-Greenstein ``g``).

    ``requested = "auto"``: the dipole where its predicted error is at most a quarter of
    ``target`` (relative), else the transport tables (module docstring); ``"dipole"`` or
    ``"transport"`` is obeyed, with its predicted error stated (``transport`` where the tables
    do not cover the medium raises ``ValueError`` naming the value). ``texels``
    (:func:`map_media`) is a parameter map's spread: ``auto`` keeps the dipole only where every
    one of them is within its share too.
    """
    if requested not in MODELS:
        raise ValueError(f"profile must be one of {', '.join(MODELS)}; got {requested!r}.")
    if not 0 < target < 1:
        raise ValueError(f"target must lie in (0, 1) (a relative error); got {target!r}.")
    dipole_error, transport_error, reason = predicted_errors(medium, g=g)
    if dipole_error is None:
        if requested == "transport":
            raise ValueError(reason)
        why = ("auto: " if requested == "auto" else "set by the scene; ") + \
              f"the transport tables do not cover this medium ({reason}), so the dipole's error is not known"
        return ProfileChoice("dipole", requested, why, target)
    dip = f"the dipole's R_d is {_channels(dipole_error)} % off the transport truth's (R / G / B)"
    tables = f"the tables' own error {100 * np.max(transport_error):.2g} %"
    if requested == "auto":
        share = target / 4
        worst = float(np.max(np.abs(dipole_error)))
        model = "dipole" if worst <= share else "transport"
        why = f"auto: {dip}, {'<=' if model == 'dipole' else '>'} a quarter of the target ({100 * share:.2g} %)"
        why += "; the dipole's Gaussians are cheaper" if model == "dipole" else f"; {tables}"
    else:
        model = requested
        why = f"set by the scene; predicted error: {dip if model == 'dipole' else tables}"
        if model == "dipole":
            why += " (profile = \"transport\" removes it)"
    choice = ProfileChoice(model, requested, why, target, dipole_error, transport_error)
    if requested == "auto" and model == "dipole" and texels is not None:
        return _over_map(choice, texels, g)
    return choice
