"""Measured homogeneous materials: Jensen et al. 2001 and Narasimhan et al. 2006, with provenance.

**The library** (:func:`material`, :func:`material_names`, :func:`material_entry`): 47
materials, each with sigma_a and reduced scattering sigma_s' in 1/mm (R, G, B), the
Henyey-Greenstein g, the relative index eta, and where every number came from (the source's
citation and table, its units, the conversion applied, the uncertainty where one is given).
The data ship as ``jsss/data/materials.json``, read once on first use; ``docs/materials.md``
has the table and a swatch of each.

- Jensen, Marschner, Levoy, Hanrahan 2001, Fig. 5(b): the 12 materials measured with the
  dipole (sigma_s' only; g is not given and stored as 0).
- Narasimhan, Gupta, Donner, Ramamoorthi, Nayar, Jensen 2006, "Acquiring scattering
  properties of participating media by dilution": 35 liquids and powders at natural
  concentration, sigma_a and sigma_s' as pbrt-v4 tabulates them (``src/pbrt/media.cpp``,
  Apache-2.0, mm^-1), sigma_s and the per-channel g as Mitsuba 0.5 does
  (``src/medium/materials.h``); eta = 1.33 assumed (neither gives one).

**The Jensen 2001 table** (:func:`jensen2001`, :func:`jensen2001_names`,
:func:`jensen2001_table`): the same 12 rows with the diffuse reflectance the paper publishes
beside them, transcribed from ``shared/papers/jensen2001-practical-model.txt``.
"""

from __future__ import annotations

import difflib
import functools
import json
import re
from importlib import resources
from typing import NamedTuple

import numpy as np

from .medium import Medium

__all__ = ["LibraryEntry", "MeasuredMaterial", "Source", "jensen2001", "jensen2001_names", "jensen2001_table",
           "material", "material_entry", "material_names"]


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
    return _medium(row.sigma_a, row.sigma_s_prime, row.eta, dtype)


# ----------------------------------------------------------------------------- the library
class Source(NamedTuple):
    """Where a material's numbers come from: one paper, and how they reached jsss."""

    key: str               # "jensen2001", "narasimhan2006"
    short: str             # "Jensen 2001"
    citation: str          # authors, title, venue
    table: str             # the table or figure
    units: str             # as the source gives them
    conversion: str        # what was done to reach sigma_a, sigma_s' [1/mm]
    g: str                 # where g comes from
    eta: str               # where eta comes from, or the assumption
    uncertainty: str       # as the source gives it, or that it gives none
    transcribed_from: str  # the files (and commits) the numbers were read from


class LibraryEntry(NamedTuple):
    """One measured material: coefficients in 1/mm (R, G, B) and its :class:`Source`.

    ``sigma_s_prime`` is the reduced scattering coefficient :math:`\\sigma_s (1 - g)`;
    ``sigma_s`` the real one where the source gives it (None where it gives sigma_s' only),
    ``g`` the Henyey-Greenstein mean cosine per channel (0 where the source gives none: see
    ``source.g``). ``diffuse_reflectance`` is the total the source publishes beside them (None
    where it publishes none).
    """

    name: str                                       # library key: lowercase, underscores
    label: str                                      # as the source spells it
    source: Source
    sigma_a: tuple[float, float, float]             # 1/mm
    sigma_s_prime: tuple[float, float, float]       # 1/mm
    sigma_s: tuple[float, float, float] | None      # 1/mm
    g: tuple[float, float, float]
    eta: float
    diffuse_reflectance: tuple[float, float, float] | None
    note: str                                       # what is particular to this entry ("" if nothing)

    @property
    def g_mean(self) -> float:
        """One g for renderers that take a scalar: the mean over the channels that scatter
        (a channel with sigma_s' = 0 carries a meaningless g = 0 in the source)."""
        scattering = [g for g, s in zip(self.g, self.sigma_s_prime) if s > 0]
        return float(np.mean(scattering)) if scattering else 0.0


def _key(name: str) -> str:
    """The library key of a name as a user or a source spells it ("Head & Shoulders Shampoo")."""
    return re.sub(r"[^a-z0-9]+", "_", str(name).lower().replace("&", "and")).strip("_")


@functools.lru_cache(maxsize=None)
def _library() -> dict[str, LibraryEntry]:
    with resources.files("jsss.data").joinpath("materials.json").open("rb") as handle:
        data = json.load(handle)
    sources = {key: Source(key=key, **fields) for key, fields in data["sources"].items()}

    def triple(values):
        return None if values is None else tuple(float(v) for v in values)

    entries = {}
    for row in data["materials"]:
        entry = LibraryEntry(row["name"], row["label"], sources[row["source"]], triple(row["sigma_a"]),
                             triple(row["sigma_s_prime"]), triple(row.get("sigma_s")), triple(row["g"]),
                             float(row["eta"]), triple(row.get("diffuse_reflectance")), row.get("note", ""))
        if entry.name in entries or entry.name != _key(entry.name):
            raise RuntimeError(f"jsss/data/materials.json: name {entry.name!r} repeated or not a library key")
        entries[entry.name] = entry
    return entries


def material_names() -> tuple[str, ...]:
    """The library's names: Jensen 2001's twelve first, then Narasimhan 2006's, each in its
    source's order."""
    return tuple(_library())


def material_entry(name: str) -> LibraryEntry:
    """The full record of a material, provenance included (see :class:`LibraryEntry`).

    ``name`` is matched without case, with any run of spaces, hyphens or punctuation read as
    one underscore and "&" as "and": "Regular Milk", "regular-milk" and "regular_milk" are one.

    Raises
    ------
    ValueError
        Unknown name; the message names the closest library names.
    """
    library = _library()
    try:
        return library[_key(name)]
    except KeyError:
        key = _key(name)
        # names that contain what was typed ("milk"), then the nearest spellings ("marbel")
        close = [n for n in library if key and key in n][:6]
        close += [n for n in difflib.get_close_matches(key, list(library), n=4, cutoff=0.6) if n not in close]
        hint = (f"did you mean {', '.join(close)}?" if close
                else f"one of {', '.join(library)}")
        raise ValueError(f"unknown material {name!r}; {hint} ('jsss materials' lists all {len(library)}).") from None


def material(name: str, *, dtype=None) -> Medium:
    """The RGB :class:`~jsss.Medium` (sigma_a, sigma_s' in 1/mm, eta) of a library material.

    The medium carries sigma_s', which is what the dipole, the multipole and the transport
    tables need; g is in :func:`material_entry` (``.g`` per channel, ``.g_mean``) for the
    renderers that take the real sigma_s and a phase function.

    Parameters
    ----------
    name : str
        One of :func:`material_names`, in any case (see :func:`material_entry`).
    dtype : optional, keyword-only
        Floating dtype of the arrays (default: JAX's default float).

    Raises
    ------
    ValueError
        Unknown name; the message names the closest ones.

    Examples
    --------
    >>> material("Regular Milk").sigma_s_prime
    Array([4.5513, 5.8294, 7.136 ], dtype=float...)
    >>> material("marble").eta
    Array([1.5, 1.5, 1.5], dtype=float...)
    """
    entry = material_entry(name)
    return _medium(entry.sigma_a, entry.sigma_s_prime, entry.eta, dtype)


def _medium(sigma_a, sigma_s_prime, eta, dtype) -> Medium:
    dtype = dtype or (np.float64 if _x64() else np.float32)
    return Medium(np.asarray(sigma_a, dtype=dtype), np.asarray(sigma_s_prime, dtype=dtype), np.full(3, eta, dtype=dtype))


def _x64() -> bool:
    import jax

    return bool(jax.config.jax_enable_x64)
