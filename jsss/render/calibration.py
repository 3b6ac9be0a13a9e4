"""The measured accuracy and cost of each rendering method, and predictions from them.

``benchmarks/methods.py --calibrate`` renders the example scenes (near, and far with the
camera moved back) with every method and knob, measures each frame's error against a
brute-force surface integral of the exact profile and its time, and writes
``calibration.json`` next to this module. The planner reads that table; nothing here is a
tuned constant.

The error of a method depends mostly on how many pixels the profile spans (its RMS
radius over one pixel's footprint, the *blur*): Lambert's error shrinks as the blur falls
below a pixel (down to the dimming diffusion causes on a curved object, about v/R^2) and
grows with many; image-space noise grows with the blur. So a prediction for a new scene
takes, per method and knob, the worst error among calibration frames whose blur lies
within a factor 2 of the scene's (or the nearest frame's when none does), scales the
measured frame time by the work (pixels for pixel methods, texels for texture space) and
adds the method's own preparation (scaled too for texture space's texel bake). Frames of
objects with open edges (a plane) are kept apart from closed ones: light that leaves
through an open edge is lost in the reference and in image-space integration but kept by
the others.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["CalibrationRow", "MethodEstimate", "choose_method", "default_calibration_path", "estimate_methods",
           "knob_label", "load_calibration", "parse_knob", "save_calibration"]

METHODS = ("lambert", "normal filtering", "image-space", "texture-space")
_NEIGHBOURHOOD = 2.0  # calibration frames within this factor of blur count as alike


@dataclass(frozen=True)
class CalibrationRow:
    """One measured frame: ``error`` relative RMS against the reference, ``ms`` per frame,
    ``prep_ms`` the method's own one-time work (the normal filter, the texel bake; the camera
    raster and shadow maps every method shares are left out), ``work`` the pixels (or
    texels for texture space) it processed, ``closed`` whether the object's surface has no
    open boundary."""

    scene: str
    blur_pixels: float
    method: str
    knob: str
    error: float
    ms: float
    work: int
    prep_ms: float = 0.0
    closed: bool = True

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"calibration row for {self.scene!r}: unknown method {self.method!r}; one of {METHODS}.")


@dataclass(frozen=True)
class MethodEstimate:
    """Predicted error and time of one method and knob for a scene, and what they rest on."""

    method: str
    knob: str
    error: float
    ms: float
    basis: str


def knob_label(method: str, *, samples: int = 32, normal_filter: str = "spectral", target: float = 0.05) -> str:
    """The knob of a calibration row: ``"32 spp"``, ``"spectral"``, ``"profile 5 %"`` or ``""``."""
    if method == "image-space":
        return f"{samples} spp"
    if method == "normal filtering":
        return normal_filter
    if method == "texture-space":
        return f"profile {100 * target:g} %"
    return ""


def parse_knob(method: str, knob: str) -> dict:
    """Inverse of :func:`knob_label`: the planner's keyword arguments for a row's knob."""
    try:
        if method == "image-space":
            return {"samples": int(knob.split()[0])}
        if method == "normal filtering":
            return {"normal_filter": knob}
        if method == "texture-space":
            return {"target": float(knob.split()[1]) / 100}
    except (IndexError, ValueError):
        raise ValueError(f"calibration knob {knob!r} of {method} is not of the form {knob_label(method)!r}.") from None
    return {}


def default_calibration_path() -> Path:
    return Path(__file__).with_name("calibration.json")


def load_calibration(path=None) -> tuple[CalibrationRow, ...]:
    """Rows of a calibration table (default: the one shipped with jsss)."""
    path = Path(path or default_calibration_path())
    try:
        data = json.loads(path.read_text())
        rows = tuple(CalibrationRow(**row) for row in data["rows"])
    except FileNotFoundError:
        raise ValueError(f"{path}: no calibration table; run `python benchmarks/methods.py --calibrate`.") from None
    except (json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{path}: not a calibration table ({error}); "
                         "rerun benchmarks/methods.py --calibrate.") from None
    if not rows:
        raise ValueError(f"{path}: the calibration table has no rows.")
    return rows


def save_calibration(rows, path=None, *, measured: str = "") -> Path:
    """Write rows atomically (a half-written table would mislead every later plan)."""
    path = Path(path or default_calibration_path())
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"measured": measured, "rows": [asdict(r) for r in rows]}, indent=1) + "\n")
    tmp.replace(path)
    return path


def estimate_methods(rows, blur_pixels: float, work: dict, *, closed: bool = True) -> list[MethodEstimate]:
    """Predicted error and time of every (method, knob) in ``rows`` for a scene.

    Parameters
    ----------
    rows : iterable of CalibrationRow
    blur_pixels : float
        The scene's profile RMS radius over its pixel footprint.
    work : dict
        Pixels (for pixel methods) or texels (``"texture-space"``) the scene would process,
        keyed by method.
    closed : bool
        Whether the scene's surface is closed; frames of the same kind are preferred (at an
        open edge light leaves the object, which only image-space integration accounts for).
    """
    groups: dict = {}
    for row in rows:
        groups.setdefault((row.method, row.knob), []).append(row)
    estimates = []
    blur = max(blur_pixels, 1e-6)
    for (method, knob), everything in groups.items():
        group = [r for r in everything if r.closed == closed] or everything
        kind = "closed" if closed else "open"
        distance = np.array([abs(np.log(max(r.blur_pixels, 1e-6) / blur)) for r in group])
        alike = [r for r, d in zip(group, distance) if d <= np.log(_NEIGHBOURHOOD)]
        if alike:
            worst = max(alike, key=lambda r: r.error)
            basis = (f"worst of {len(alike)} {kind}-surface frame(s) at blur "
                     f"{blur / _NEIGHBOURHOOD:.3g}-{blur * _NEIGHBOURHOOD:.3g} px")
        else:
            worst = group[int(np.argmin(distance))]
            basis = f"nearest frame {worst.scene} at blur {worst.blur_pixels:.3g} px"
        # One frame with its own preparation: what rendering this scene once costs. Frames
        # scale with the work; so does texture space's texel bake, while the normal filter's
        # preparation is mostly the mesh's eigenvectors, which do not follow the pixels.
        ms = float(np.median([r.ms * work[method] / r.work
                              + r.prep_ms * (work[method] / r.work if method == "texture-space" else 1.0)
                              for r in (alike or [worst])]))
        estimates.append(MethodEstimate(method, knob, worst.error, ms, basis))
    return sorted(estimates, key=lambda e: e.ms)


def choose_method(estimates, target: float):
    """The cheapest estimate whose predicted error meets ``target``; else the most accurate.

    Returns (MethodEstimate, why).
    """
    meeting = [e for e in estimates if e.error <= target]
    if meeting:
        best = min(meeting, key=lambda e: e.ms)
        return best, (f"cheapest method predicted to meet {100 * target:.3g} %: {best.method}"
                      + (f" ({best.knob})" if best.knob else "")
                      + f", {100 * best.error:.2g} % in {best.ms:.3g} ms ({best.basis})")
    best = min(estimates, key=lambda e: e.error)
    return best, (f"no method is predicted to meet {100 * target:.3g} %; the most accurate: {best.method}"
                  + (f" ({best.knob})" if best.knob else "") + f", {100 * best.error:.2g} % ({best.basis})")
