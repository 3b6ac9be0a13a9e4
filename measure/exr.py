"""OpenEXR images in and out, with errors that name the file (used by measure/ and the render command).

Images are float arrays of shape ``(H, W, C)`` with named channels (``("R", "G", "B")``
or ``("Y",)``). Pixels are stored as ``"float"`` (32-bit) or ``"half"`` (16-bit).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["ExrError", "ExrImage", "read_exr", "write_exr"]

_PIXEL_TYPES = {"float": np.float32, "half": np.float16}


class ExrError(ValueError):
    """An EXR file could not be read or written, or its content is not usable."""


class ExrImage:
    """Pixels ``(H, W, C)`` as float64, the channel names and the header's attributes."""

    __slots__ = ("pixels", "channels", "header", "path")

    def __init__(self, pixels: np.ndarray, channels: tuple[str, ...], header: dict, path: Path):
        self.pixels = pixels
        self.channels = channels
        self.header = header
        self.path = path

    def __repr__(self) -> str:
        return f"ExrImage({str(self.path)!r}, shape={self.pixels.shape}, channels={self.channels})"


def _plain_attributes(header: dict) -> dict:
    """Header attributes as plain Python values (the structural ones left out)."""
    skip = {"channels", "dataWindow", "displayWindow", "compression", "lineOrder", "type",
            "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth"}
    plain = {}
    for key, value in header.items():
        if key in skip:
            continue
        if isinstance(value, (str, int, float)):
            plain[key] = value
        elif isinstance(value, np.ndarray):
            plain[key] = value.tolist()
    return plain


@contextlib.contextmanager
def _library_output():
    """Capture what OpenEXR's C++ library prints (to stdout and stderr) while it reads: on stdout
    it would corrupt a command's ``--json``, and on stderr it would put a second line before
    the command's one-line error. Yields a list that holds the text afterwards."""
    import tempfile

    captured: list[str] = []
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = os.dup(1), os.dup(2)
    except (OSError, ValueError, AttributeError):  # no real file descriptors (a notebook, a test capture)
        yield captured
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield captured
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            captured.append(sink.read().decode("utf-8", "replace"))


def read_exr(path, channels: Sequence[str] | None = None, *, allow_nonfinite: bool = False) -> ExrImage:
    """Read an EXR image.

    Parameters
    ----------
    path : str or Path
    channels : sequence of str, optional
        Channels to return, in this order (e.g. ``("R", "G", "B")``). Default: ``R, G, B``
        when present, else ``Y``, else every channel in alphabetical order.
    allow_nonfinite : bool, keyword-only
        Accept NaN/Inf pixels (default: they raise).

    Raises
    ------
    ExrError
        Missing or unreadable file, missing channel, non-finite pixels; the message names
        the file.
    """
    import OpenEXR

    from jsss.render.surface_maps import checked_exr_size

    path = Path(path)
    if not path.is_file():
        raise ExrError(f"{path}: no such file")
    try:
        checked_exr_size(path)  # before OpenEXR allocates what the header declares
    except ValueError as error:
        raise ExrError(str(error)) from None
    try:
        with _library_output() as printed, OpenEXR.File(str(path), separate_channels=True) as exr:
            header = dict(exr.header())
            available = {name: np.asarray(ch.pixels) for name, ch in exr.channels().items()}
    except Exception as error:  # OpenEXR raises RuntimeError with its own wording
        said = next((line.strip() for line in "".join(printed).splitlines() if line.strip()), "")
        said = said.removeprefix(f"{path}:").strip()[:160]  # its first line says what is wrong; the rest repeats it
        raise ExrError(f"{path}: truncated or not a readable OpenEXR file ({said or error})") from None
    if "".join(printed).strip():  # a warning on a file that did read: keep it, on stderr
        print("".join(printed).rstrip(), file=sys.stderr)
    if channels is None:
        if all(c in available for c in "RGB"):
            channels = ("R", "G", "B")
        elif "Y" in available:
            channels = ("Y",)
        else:
            channels = tuple(sorted(c for c in available if c != "A"))
            if not channels:
                raise ExrError(f"{path}: holds only an alpha channel (A); an image of light needs R, G, B or Y")
    missing = [c for c in channels if c not in available]
    if missing:
        raise ExrError(f"{path}: missing channel(s) {missing}; the file has {sorted(available)}")
    pixels = np.stack([available[c].astype(np.float64) for c in channels], axis=-1)
    if not allow_nonfinite:
        bad = int(pixels.size - np.count_nonzero(np.isfinite(pixels)))
        if bad:
            raise ExrError(f"{path}: {bad} NaN/Inf pixel value(s); fix or mask the image first")
    return ExrImage(pixels, tuple(channels), _plain_attributes(header), path)


def write_exr(path, pixels, channels: Sequence[str] = ("R", "G", "B"), *, pixel_type: str = "float",
              attributes: dict | None = None) -> Path:
    """Write ``pixels`` (H, W) or (H, W, C) as an EXR, atomically (temp file, then rename).

    Parameters
    ----------
    path : str or Path
    pixels : array_like
        Linear values; a 2-D array is one channel.
    channels : sequence of str
        One name per channel.
    pixel_type : {"float", "half"}, keyword-only
    attributes : dict, optional, keyword-only
        Extra header attributes (str, int or float values).

    Raises
    ------
    ExrError
        Shape and channel names disagree, unknown pixel type, or the file cannot be written.
    """
    import OpenEXR

    path = Path(path)
    if pixel_type not in _PIXEL_TYPES:
        raise ExrError(f"{path}: pixel_type must be one of {sorted(_PIXEL_TYPES)}; got {pixel_type!r}")
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    if pixels.ndim != 3 or pixels.shape[-1] != len(channels):
        raise ExrError(f"{path}: pixels of shape {pixels.shape} do not match channels {tuple(channels)}")
    data = {name: np.ascontiguousarray(pixels[..., i].astype(_PIXEL_TYPES[pixel_type]))
            for i, name in enumerate(channels)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update(attributes or {})
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}.exr")
    try:
        with OpenEXR.File(header, data) as exr:
            exr.write(str(tmp))
        os.replace(tmp, path)
    except Exception as error:
        tmp.unlink(missing_ok=True)
        raise ExrError(f"{path}: could not write ({error})") from None
    return path
