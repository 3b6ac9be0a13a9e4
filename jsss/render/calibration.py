"""The measured accuracy and cost of each rendering method, and predictions from them.

``benchmarks/methods.py --calibrate`` renders the calibration scenes (near, and far with the
camera moved back) with every method and knob, measures each frame's error against a
brute-force surface integral of the transport truth's profile (the transport tables wherever
they cover the medium, a stack's layered profile; ``jsss.render.reference``) and its time,
and writes ``jsss/data/calibration.json``. The frames render with the profile the scene's
``profile = "auto"`` picks, so an error holds the method's own error, its Gaussian fit of that
profile and, where auto keeps the dipole, the dipole's distance from transport (until
2026-12-04 the reference integrated the frame's own, then dipole, profile: a consistency
check that never saw how a few Gaussians follow the transport profile's 1/r core). The
planner reads that table; nothing here is a tuned constant.

The error of a method depends on what the frame shows, described by
:class:`FrameFeatures`, all independent of the image's resolution:

* **the profile's reach in the frame** (its RMS radius over the frame's height at the object,
  ``blur_frame``): Lambert's error shrinks as it falls (down to the dimming diffusion causes on
  a curved object, about v/R^2) and grows with it; image-space noise grows with it. The RMS
  radius in *pixels* (the feature until 2026-12-02) is not it: the same framing at 320 x 240
  spans 3.3x the pixels of the calibration's 96 x 72, and matched the backlit skin to the
  calibration's half-distance frames (Lambert 2.9 %) instead of its own framing (6.2 %);
* **open or closed surface**: light that leaves through an open edge is lost in the reference
  and in image-space integration but kept by the others;
* **light from behind** (``backlit``: the share of the irradiance at the object from lights
  that travel towards the camera): the light the camera sees then arrives through the
  object, around its silhouette, which a method without spread (Lambert, normal filtering)
  cannot show;
* **curvature** (the profile's RMS radius over the object's radius; 0 for a plane): the
  dimming of a curved surface and the light wrapping past its terminator.

A prediction for a new frame takes, per method and knob, the worst error among calibration
frames *alike* in all four (the same surface kind and lighting class, curvature and reach
within a factor 2), so the planner never picks a method whose measured error on a similar
frame exceeds the target. With no alike frame it takes the worst of the frames of the same
surface kind and lighting class (else of all), and says so: extrapolating is done
pessimistically. Time scales the measured frame time by the work (pixels for pixel methods,
texels for texture space) and adds the method's own preparation (scaled too for texture
space's texel bake). :func:`leave_one_scene_out` predicts each calibration scene from the
others, the check of these features ``benchmarks/methods.py`` prints.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .passes import Method

__all__ = ["CalibrationRow", "FrameFeatures", "MethodEstimate", "choose_method", "default_calibration_path",
           "estimate_methods", "knob_label", "leave_one_scene_out", "load_calibration", "parse_knob",
           "save_calibration"]

METHODS = tuple(Method)
_NEIGHBOURHOOD = 2.0  # calibration frames within this factor of reach and of curvature count as alike
BACKLIT = 0.5  # a frame is back-lit when at least this share of its irradiance travels towards the camera
FLAT = 0.02  # curvature (RMS radius / object radius) below which a surface counts as flat


@dataclass(frozen=True)
class FrameFeatures:
    """What decides a method's error on a frame (module docstring).

    ``blur_pixels``: the profile's RMS radius over one pixel's footprint at the object's
    nearest point; ``blur_frame``: the same over the frame's height there (resolution-free);
    ``closed``: the surface has no open boundary; ``backlit``: share in [0, 1] of the
    irradiance at the object from lights travelling towards the camera; ``curvature``: the
    RMS radius over the object's bounding radius (0 for an open surface).
    """

    blur_pixels: float
    blur_frame: float
    closed: bool = True
    backlit: float = 0.0
    curvature: float = 0.0

    def describe(self) -> str:
        light = "back-lit" if self.backlit >= BACKLIT else "front-lit"
        shape = "closed" if self.closed else "open"
        bend = "flat" if self.curvature < FLAT else f"curvature {self.curvature:.2g}"
        return (f"{shape}, {light} ({100 * self.backlit:.0f} % from behind), {bend}, "
                f"reach {self.blur_frame:.3g} of the frame")


@dataclass(frozen=True)
class CalibrationRow:
    """One measured frame: ``error`` relative RMS against the reference, ``ms`` per frame,
    ``prep_ms`` the method's own one-time work (the normal filter, the texel bake; the camera
    raster and shadow maps every method shares are left out), ``work`` the pixels (or
    texels for texture space) it processed, ``closed`` whether the object's surface has no
    open boundary, ``fixed_ms`` the part of ``ms`` that does not grow with the work (the
    pixel methods' frame at a tiny resolution: per-frame solves such as the oblique-incidence
    law's H function; 0 where not measured)."""

    scene: str
    blur_pixels: float
    method: str
    knob: str
    error: float
    ms: float
    work: int
    prep_ms: float = 0.0
    closed: bool = True
    blur_frame: float = float("nan")  # nan: a table from before 2026-12-02, matched by blur_pixels
    backlit: float = 0.0
    curvature: float = 0.0
    fixed_ms: float = 0.0

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"calibration row for {self.scene!r}: unknown method {self.method!r}; one of {METHODS}.")

    @property
    def features(self) -> FrameFeatures:
        return FrameFeatures(self.blur_pixels, self.blur_frame, self.closed, self.backlit, self.curvature)


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
    if method == Method.IMAGE_SPACE:
        return f"{samples} spp"
    if method == Method.NORMAL_FILTERING:
        return normal_filter
    if method == Method.TEXTURE_SPACE:
        return f"profile {100 * target:g} %"
    return ""


def parse_knob(method: str, knob: str) -> dict:
    """Inverse of :func:`knob_label`: the planner's keyword arguments for a row's knob."""
    try:
        if method == Method.IMAGE_SPACE:
            return {"samples": int(knob.split()[0])}
        if method == Method.NORMAL_FILTERING:
            return {"normal_filter": knob}
        if method == Method.TEXTURE_SPACE:
            return {"target": float(knob.split()[1]) / 100}
    except (IndexError, ValueError):
        raise ValueError(f"calibration knob {knob!r} of {method} is not of the form {knob_label(method)!r}.") from None
    return {}


def default_calibration_path() -> Path:
    return Path(__file__).resolve().parent.parent / "data" / "calibration.json"


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


def _within(a: float, b: float, factor: float = _NEIGHBOURHOOD) -> bool:
    return abs(np.log(max(a, 1e-6) / max(b, 1e-6))) <= np.log(factor)


def _same_kind(row: CalibrationRow, features: FrameFeatures) -> bool:
    """The same surface kind (open or closed) and lighting class (front- or back-lit)."""
    return row.closed == features.closed and (row.backlit >= BACKLIT) == (features.backlit >= BACKLIT)


def _alike(row: CalibrationRow, features: FrameFeatures) -> bool:
    """Alike in all features: kind, lighting, curvature and the profile's reach (module docstring)."""
    if not _same_kind(row, features):
        return False
    flat = row.curvature < FLAT, features.curvature < FLAT
    if flat[0] != flat[1] or not (flat[0] or _within(row.curvature, features.curvature)):
        return False
    if np.isnan(row.blur_frame):  # an old table: reach in pixels
        return _within(row.blur_pixels, features.blur_pixels)
    return _within(row.blur_frame, features.blur_frame)


def estimate_methods(rows, features: FrameFeatures, work: dict) -> list[MethodEstimate]:
    """Predicted error and time of every (method, knob) in ``rows`` for a frame.

    Parameters
    ----------
    rows : iterable of CalibrationRow
    features : FrameFeatures
        The frame's features (:func:`jsss.render.planner.frame_features`).
    work : dict
        Pixels (for pixel methods) or texels (``"texture-space"``) the scene would process,
        keyed by method.
    """
    if not isinstance(features, FrameFeatures):
        raise TypeError(f"estimate_methods(features=...) takes a FrameFeatures; got {type(features).__name__} "
                        "(a blur in pixels alone no longer decides; see jsss.render.calibration).")
    groups: dict = {}
    for row in rows:
        groups.setdefault((row.method, row.knob), []).append(row)
    estimates = []
    for (method, knob), everything in groups.items():
        alike = [r for r in everything if _alike(r, features)]
        if alike:
            basis_rows = alike
            basis = f"worst of {len(alike)} alike frame(s): {', '.join(sorted({r.scene for r in alike}))}"
        else:
            basis_rows = [r for r in everything if _same_kind(r, features)] or everything
            basis = (f"no alike frame; worst of {len(basis_rows)} frame(s) of "
                     f"{', '.join(sorted({r.scene for r in basis_rows}))}")
        worst = max(basis_rows, key=lambda r: r.error)
        # One frame with its own preparation: what rendering this scene once costs. Frames
        # scale with the work, beyond their fixed part (a homogeneous medium's oblique law, 1 ms
        # of a 96 x 72 Lambert frame, scaled with the pixels had made Lambert at 320 x 240 look
        # 4x slower than it is); so does texture space's texel bake, while the normal filter's
        # preparation is mostly the mesh's eigenvectors, which do not follow the pixels.
        ms = float(np.median([r.fixed_ms + (r.ms - r.fixed_ms) * work[method] / r.work
                              + r.prep_ms * (work[method] / r.work if method == Method.TEXTURE_SPACE else 1.0)
                              for r in basis_rows]))
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


def leave_one_scene_out(rows, target: float) -> list[dict]:
    """Predict each calibration scene's frames from the other scenes' rows alone.

    For every frame of every scene: each (method, knob)'s predicted error beside its measured
    one, and the method the planner would choose at ``target`` with that choice's measured
    error. Returns one dict per frame: ``scene``, ``features``, ``chosen`` (method, knob),
    ``predicted`` and ``measured`` (of the choice), ``meets`` (measured <= target), ``alike``
    (whether the choice's prediction rests on alike frames rather than the pessimistic
    fallback), ``basis`` (its one-line reason) and ``errors``: {(method, knob): (predicted, measured)}.
    """
    rows = tuple(rows)
    out = []
    for scene in dict.fromkeys(r.scene for r in rows):
        others = [r for r in rows if r.scene != scene]
        frames: dict = {}
        for r in rows:
            if r.scene == scene:
                frames.setdefault((r.blur_pixels, r.blur_frame), []).append(r)
        for frame in frames.values():
            measured = {(r.method, r.knob): r for r in frame}
            work = {r.method: r.work for r in frame}
            comparable = [r for r in others if (r.method, r.knob) in measured]
            estimates = estimate_methods(comparable, frame[0].features, work)
            if not estimates:  # no method of this frame was measured on any other scene
                continue
            chosen, _ = choose_method(estimates, target)
            truth = measured[(chosen.method, chosen.knob)].error
            out.append(dict(scene=scene, features=frame[0].features, chosen=(chosen.method, chosen.knob),
                            predicted=chosen.error, measured=truth, meets=truth <= target,
                            alike=not chosen.basis.startswith("no alike"), basis=chosen.basis,
                            errors={(e.method, e.knob): (e.error, measured[(e.method, e.knob)].error)
                                    for e in estimates}))
    return out
