"""A beam-profile measurement from its files: read, checked, per unit exposure, fitted.

:func:`read_measurement` reads the measurement (one image, or exposure brackets to merge),
the white reference and an optional dark frame, in any format :func:`measure.photo.read_image`
reads, and returns them as arrays per unit exposure with the dark frame off
(:class:`MeasurementImages`). :func:`fit_images` fits them with
:func:`measure.pipeline.fit_measurement`. ``fit-params`` and ``fit-params batch`` are these two
calls; nothing here prints or writes.

Every error is a ``ValueError`` (``measure.exr.ExrError`` for unreadable files,
:class:`measure.checks.MeasurementError` for images that cannot be a measurement) whose one-line
message names the file or the argument. ``names`` lets a caller say how its user spells an
argument (a command passes its options, ``{"eta": "--eta"}``), as ``check_image(name=...)`` does.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checks import MeasurementError
from .exr import ExrError, ExrImage

__all__ = ["MeasurementImages", "check_options", "fit_images", "read_measurement"]


@dataclass(frozen=True)
class MeasurementImages:
    """A measurement and its white reference as read from their files.

    Attributes
    ----------
    measurement, reference : ndarray, float64, shape ``(H, W, C)``
        Pixels per unit exposure (the file's ``jsss_exposure``: exposure time [s] x ISO / 100,
        1 where the file records none), the dark frame subtracted. Merged exposure brackets
        are per unit exposure by construction.
    channels : tuple of str
        The channel names (``("R", "G", "B")`` for camera files).
    pixel_mm : float or None
        The pixel size on the sample [mm] recorded in the measurement's header
        (``jsss_pixel_mm``), or None.
    measurement_path, reference_path : Path
        The files (the first bracket for merged brackets), for messages.
    """

    measurement: np.ndarray
    reference: np.ndarray
    channels: tuple[str, ...]
    pixel_mm: float | None
    measurement_path: Path
    reference_path: Path


def _name(names: Mapping[str, str] | None, parameter: str) -> str:
    return (names or {}).get(parameter, parameter)


def _choice(names: Mapping[str, str] | None, parameter: str, value: str) -> str:
    """``--model transport`` as a command spells it, ``model='transport'`` as Python does."""
    return f"{names[parameter]} {value}" if names and parameter in names else f"{parameter}={value!r}"


def check_options(*, eta, pixel_mm=None, reference_reflectance=0.99, view_angle_deg=None, model="transport",
                  g=0.0, names: Mapping[str, str] | None = None) -> None:
    """Refuse (ValueError naming the option as ``names`` spells it) a fit's option out of its
    range; ``eta`` and ``pixel_mm`` None are not checked (a manifest's row or a file's header
    may give them). A batch calls this before its first fit, so that a bad flag is one line,
    not one failed row per image."""
    if eta is not None and not (np.isfinite(eta) and eta > 0):
        raise ValueError(f"{_name(names, 'eta')} must be > 0 (the relative index of refraction, e.g. 1.3); got {eta}")
    if pixel_mm is not None and not (np.isfinite(pixel_mm) and pixel_mm > 0):
        raise ValueError(f"{_name(names, 'pixel_mm')} must be > 0 (the pixel size on the sample in mm); "
                         f"got {pixel_mm:g}")
    if not (0 < reference_reflectance <= 1):  # also refuses nan
        raise ValueError(f"{_name(names, 'reference_reflectance')} must be in (0, 1] (0.99 for Spectralon); "
                         f"got {reference_reflectance:g}")
    if view_angle_deg is not None and not (0 <= view_angle_deg < 90):  # also refuses nan
        raise ValueError(f"{_name(names, 'view_angle_deg')} must lie in [0, 90) degrees (the camera's angle from "
                         f"the normal); got {view_angle_deg:g}")
    if model == "transport" and eta is not None:
        from jsss import transport

        try:
            transport.check_supported(eta, g)
        except ValueError as error:
            raise ValueError(f"{_choice(names, 'model', 'transport')}: {error} ({_choice(names, 'model', 'dipole')} "
                             "fits any eta, with diffusion's bias)") from None


def read_measurement(measurement, reference, *, dark=None, saturation: float | None = None,
                     white_balance: str = "none", names: Mapping[str, str] | None = None) -> MeasurementImages:
    """Read a measurement, its white reference and dark frame, and check them.

    Parameters
    ----------
    measurement : path, or sequence of paths
        The beam-profile image: OpenEXR (linear HDR), a camera raw file, or a 16-bit linear
        TIFF/PNG. Several paths are exposure brackets of one scene, merged
        (:func:`measure.profile.merge_brackets`) with the exposure each file records.
    reference : path
        The white reference: the same beam and camera on a white diffuse reflector.
    dark : path, optional, keyword-only
        Dark frame taken at the frames' exposure; subtracted from every frame.
    saturation : float, optional, keyword-only
        The clip level of a bracket, in the files' pixel units. Needed for EXR brackets; raw
        and integer files record their own (1.0).
    white_balance : {"none", "camera", "daylight"}, keyword-only
        Multipliers applied to raw files (default none: the reference calibrates each channel).
    names : mapping of str to str, optional, keyword-only
        How messages name the arguments (module docstring).

    Returns
    -------
    MeasurementImages
        Arrays per unit exposure with the dark frame off.

    Raises
    ------
    measure.exr.ExrError
        A file that is missing, unreadable, of an unsupported type or not finite.
    measure.checks.MeasurementError
        Brackets without an exposure time or a clip level, images of different shapes, or
        clipped pixels in a single frame or the reference (several pixels at the exact maximum
        of a channel in an EXR).
    """
    from .photo import read_image

    paths = [measurement] if isinstance(measurement, (str, os.PathLike)) else list(measurement)
    if not paths:
        raise ValueError(f"{_name(names, 'measurement')}: give at least one image")
    merged = len(paths) > 1
    # Merged brackets are per unit exposure with the dark frame already subtracted.
    if merged:  # the dark frame is read once, here, and its pixels also go into the merge
        meas, dark_image = _merge_brackets(paths, saturation, dark, white_balance, names)
    else:
        meas = read_image(paths[0], white_balance=white_balance)
        dark_image = None if dark is None else _read_like(dark, meas, white_balance)
    ref = _read_like(reference, meas, white_balance)
    for image in [ref] + ([dark_image] if dark_image else []):
        if image.pixels.shape != meas.pixels.shape:
            raise MeasurementError(f"{image.path}: shape {image.pixels.shape} differs from {meas.path} "
                                   f"{meas.pixels.shape}")
    height, width = meas.pixels.shape[:2]
    if min(height, width) < MIN_SIDE:
        raise MeasurementError(f"{meas.path}: {width} x {height} pixels is too small for a radial profile (at least "
                               f"{MIN_SIDE} x {MIN_SIDE}: the beam and the light's fall-off around it)")
    if not merged:
        _check_clipping(meas)
    _check_clipping(ref)
    # Dark frame off (it was taken at the frames' exposure), then each frame per unit exposure
    # where its file records one (raw and TIFF metadata, the EXR attribute jsss_exposure), so
    # that a measurement and a reference exposed differently calibrate correctly.
    offset = 0.0 if dark_image is None else dark_image.pixels
    meas_pixels = meas.pixels if merged else (meas.pixels - offset) / _header_number(meas, "jsss_exposure", 1.0)
    ref_pixels = (ref.pixels - offset) / _header_number(ref, "jsss_exposure", 1.0)
    sums = np.asarray(ref_pixels, float).reshape(-1, ref_pixels.shape[-1]).sum(0)
    if np.any(sums <= 0):  # (a measurement without light is named by measure.checks, with its noise)
        channel = list(ref.channels)[int(np.argmax(sums <= 0))]
        after = " after the dark frame" if dark_image is not None else ""
        raise MeasurementError(f"{ref.path}: holds no light{after} (its pixels sum to <= 0 in channel {channel}); "
                               "is it the white reference, exposed?")
    pixel_mm = _header_number(meas, "jsss_pixel_mm", None)
    return MeasurementImages(meas_pixels, ref_pixels, tuple(meas.channels), pixel_mm, Path(meas.path),
                             Path(ref.path))


def _read_like(path, meas: ExrImage, white_balance: str) -> ExrImage:
    """``path`` read with the measurement's channels; a file without them is named with the
    measurement that set them (the reference had been blamed alone)."""
    from .photo import read_image

    try:
        return read_image(path, meas.channels, white_balance=white_balance)
    except ExrError as error:
        if "missing channel" not in str(error):
            raise
        raise ExrError(f"{error}: the measurement {meas.path} has channels {list(meas.channels)}, and its "
                       "reference and dark frame need the same") from None


MIN_SIDE = 16  # pixels: below this no radial profile has bins beyond the beam (a 1 x 1 image had met an internal check)


def _header_number(image: ExrImage, key: str, default):
    """A positive, finite number from the file's header (``default`` where it has none): a bad
    one is named as the file's, not as the flag that would override it (a header pixel size of
    -1 had been blamed on --pixel-mm, an exposure of 0 on "non-finite pixel values")."""
    if key not in image.header:
        return default
    value = image.header[key]
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if not (np.isfinite(number) and number > 0):
        raise MeasurementError(f"{image.path}: the header attribute {key} is {value!r}; it must be a number > 0 "
                               "(fix the file, or remove the attribute and pass the value on the command line)")
    return number


def _merge_brackets(paths: Sequence, saturation, dark, white_balance, names) -> tuple:
    """Read exposure brackets (exposure time from each file's metadata: the EXR attribute
    ``jsss_exposure``, a raw or TIFF file's exposure time x ISO / 100) and merge them.
    Returns the merged image and the dark frame's image (None without one), read once."""
    from .photo import read_image
    from .profile import merge_brackets

    frames = [read_image(p, white_balance=white_balance) for p in paths]
    missing = [str(f.path) for f in frames if "jsss_exposure" not in f.header]
    if missing:
        raise MeasurementError(f"{missing[0]}: bracket without an exposure time (EXR header attribute jsss_exposure, "
                               "or the exposure time of a raw/TIFF file's metadata)")
    if saturation is None:
        levels = {f.header.get("jsss_saturation") for f in frames}
        if None in levels or len(levels) != 1:
            raise MeasurementError(f"several measurement frames need {_name(names, 'saturation')} (the clip level "
                                   "of a frame)")
        saturation = levels.pop()  # raw and integer files know their clip level
    dark_image = None if dark is None else read_image(dark, frames[0].channels, white_balance=white_balance)
    merged = merge_brackets([f.pixels for f in frames], [_header_number(f, "jsss_exposure", None) for f in frames],
                            saturation=saturation, dark=None if dark_image is None else dark_image.pixels,
                            names=[str(f.path) for f in frames])
    return (ExrImage(merged, frames[0].channels, {**frames[0].header, "jsss_merged": True}, frames[0].path),
            dark_image)


def _check_clipping(image: ExrImage) -> None:
    """Clipped highlights: pixels at the file's clip level (raw, TIFF, PNG), or in an EXR
    several pixels sharing the exact maximum of a channel."""
    level = image.header.get("jsss_saturation")
    if level is not None and not image.header.get("jsss_merged"):
        clipped = int(np.count_nonzero(np.any(image.pixels >= level, axis=-1)))
        if clipped:
            raise MeasurementError(f"{image.path}: {clipped} pixel(s) clipped at the sensor's saturation; use a "
                                   "shorter exposure or merge brackets")
        return
    for c, name in enumerate(image.channels):
        channel = image.pixels[..., c]
        peak = channel.max()
        if peak > 0 and np.count_nonzero(channel == peak) > 4:
            raise MeasurementError(f"{image.path}: channel {name} looks saturated ({np.count_nonzero(channel == peak)} "
                                   f"pixels at the maximum {peak:g}); use a shorter exposure or merge brackets")


def fit_images(images: MeasurementImages, eta: float, *, pixel_mm: float | None = None,
               reference_reflectance: float = 0.99, model: str = "transport", g: float = 0.0,
               view_angle_deg: float | None = 0.0, grid=None, names: Mapping[str, str] | None = None):
    """Fit sigma_a and sigma_s' per channel to a measurement read by :func:`read_measurement`.

    Parameters
    ----------
    images : MeasurementImages
    eta : float
        Relative index of refraction of the sample (dimensionless, > 0).
    pixel_mm : float, optional, keyword-only
        Pixel size on the sample [mm]; default the measurement's header (``images.pixel_mm``).
    reference_reflectance : float, keyword-only
        Total reflectance of the white reference, in (0, 1] (0.99 for Spectralon).
    model : {"dipole", "transport"}, keyword-only
        The profile model (:func:`fitting.medium.fit_medium`): ``"transport"`` (the default, as
        ``fit-params``; scaled Monte Carlo tables, exact to radiative transfer) covers eta 1.0-1.6
        and g in {0, 0.5, 0.8, 0.9}; ``"dipole"`` is diffusion.
    g : float, keyword-only
        Henyey-Greenstein g of the material (transport model).
    view_angle_deg : float or None, keyword-only
        The camera's angle from the sample's normal, in [0, 90) degrees (pixels record radiance
        toward it); None reads the pixels as exitance (a simulation's tally).
    grid : jsss.layers.hankel.HankelGrid, optional, keyword-only
        The model's Hankel grid; pass one when fitting many measurements.
    names : mapping of str to str, optional, keyword-only
        How messages name the arguments (module docstring).

    Returns
    -------
    measure.pipeline.MeasurementFit
        ``.table()`` gives the per-channel results (coefficients in 1/mm, errors, quality).

    Raises
    ------
    ValueError
        An argument out of its range (the message names it), or no pixel size at all.
    measure.checks.MeasurementError
        Images that cannot be a measurement (:func:`measure.checks.check_measurement`); the
        message names both files.
    """
    from .pipeline import fit_measurement

    if pixel_mm is None:
        pixel_mm = images.pixel_mm
        if pixel_mm is None:
            raise ValueError(f"{images.measurement_path}: no pixel size in the header (jsss_pixel_mm); pass "
                             f"{_name(names, 'pixel_mm')}")
    if eta is None:
        raise ValueError(f"{_name(names, 'eta')} must be > 0 (the relative index of refraction, e.g. 1.3); got None")
    check_options(eta=eta, pixel_mm=pixel_mm, reference_reflectance=reference_reflectance,
                  view_angle_deg=view_angle_deg, model=model, g=g, names=names)
    try:
        return fit_measurement(images.measurement, images.reference, float(pixel_mm), float(eta),
                               reference_reflectance=reference_reflectance, model=model, g=g,
                               view_angle_deg=view_angle_deg, channels=images.channels, grid=grid)
    except MeasurementError as error:
        raise MeasurementError(f"{images.measurement_path} with reference {images.reference_path}: {error}") from None
