"""Measured materials of Jensen et al. 2001, Fig. 5(b).

Reduced scattering and absorption coefficients in 1/mm for the camera's R, G, B
bands, the diffuse reflectance the paper publishes beside them, and the relative index
of refraction. Values are transcribed from the table in
``shared/papers/jensen2001-practical-model.txt``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .medium import Medium

__all__ = ["MeasuredMaterial", "jensen2001", "jensen2001_names", "jensen2001_table"]


class MeasuredMaterial(NamedTuple):
    """One row of Jensen 2001 Fig. 5(b); RGB triples as tuples of floats."""

    name: str
    sigma_s_prime: tuple[float, float, float]  # 1/mm
    sigma_a: tuple[float, float, float]  # 1/mm
    diffuse_reflectance: tuple[float, float, float]  # as published
    eta: float


_TABLE = (
    MeasuredMaterial("Apple", (2.29, 2.39, 1.97), (0.0030, 0.0034, 0.046), (0.85, 0.84, 0.53), 1.3),
    MeasuredMaterial("Chicken1", (0.15, 0.21, 0.38), (0.015, 0.077, 0.19), (0.31, 0.15, 0.10), 1.3),
    MeasuredMaterial("Chicken2", (0.19, 0.25, 0.32), (0.018, 0.088, 0.20), (0.32, 0.16, 0.10), 1.3),
    MeasuredMaterial("Cream", (7.38, 5.47, 3.15), (0.0002, 0.0028, 0.0163), (0.98, 0.90, 0.73), 1.3),
    MeasuredMaterial("Ketchup", (0.18, 0.07, 0.03), (0.061, 0.97, 1.45), (0.16, 0.01, 0.00), 1.3),
    MeasuredMaterial("Marble", (2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071), (0.83, 0.79, 0.75), 1.5),
    MeasuredMaterial("Potato", (0.68, 0.70, 0.55), (0.0024, 0.0090, 0.12), (0.77, 0.62, 0.21), 1.3),
    MeasuredMaterial("Skimmilk", (0.70, 1.22, 1.90), (0.0014, 0.0025, 0.0142), (0.81, 0.81, 0.69), 1.3),
    MeasuredMaterial("Skin1", (0.74, 0.88, 1.01), (0.032, 0.17, 0.48), (0.44, 0.22, 0.13), 1.3),
    MeasuredMaterial("Skin2", (1.09, 1.59, 1.79), (0.013, 0.070, 0.145), (0.63, 0.44, 0.34), 1.3),
    MeasuredMaterial("Spectralon", (11.6, 20.4, 14.9), (0.00, 0.00, 0.00), (1.00, 1.00, 1.00), 1.3),
    MeasuredMaterial("Wholemilk", (2.55, 3.21, 3.77), (0.0011, 0.0024, 0.014), (0.91, 0.88, 0.76), 1.3),
)
_BY_KEY = {row.name.lower(): row for row in _TABLE}


def jensen2001_names() -> tuple[str, ...]:
    """Names of the 12 measured materials, as the paper spells them."""
    return tuple(row.name for row in _TABLE)


def jensen2001_table() -> tuple[MeasuredMaterial, ...]:
    """All rows of the table, in the paper's order."""
    return _TABLE


def _row(name: str) -> MeasuredMaterial:
    try:
        return _BY_KEY[str(name).lower()]
    except KeyError:
        valid = ", ".join(jensen2001_names())
        raise ValueError(
            f"Unknown Jensen 2001 material {name!r}; valid names (any case): {valid}."
        ) from None


def jensen2001(name: str, *, dtype=None) -> Medium:
    """The RGB :class:`~jsss.Medium` of a measured material (case-insensitive name).

    Parameters
    ----------
    name : str
        One of :func:`jensen2001_names`, in any case.
    dtype : optional, keyword-only
        Floating dtype of the arrays (default: JAX's default float).

    Raises
    ------
    ValueError
        Unknown name; the message lists the valid ones.

    Examples
    --------
    >>> jensen2001("marble").eta
    Array([1.5, 1.5, 1.5], dtype=float...)
    """
    row = _row(name)
    dtype = dtype or (np.float64 if _x64() else np.float32)
    return Medium(
        np.asarray(row.sigma_a, dtype=dtype),
        np.asarray(row.sigma_s_prime, dtype=dtype),
        np.full(3, row.eta, dtype=dtype),
    )


def _x64() -> bool:
    import jax

    return bool(jax.config.jax_enable_x64)
