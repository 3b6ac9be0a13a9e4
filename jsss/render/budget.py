"""What a scene may ask of this machine's memory, checked before anything is allocated.

A scene's sizes -- the camera's ``resolution``, the ``texture_size``, the ``shadow_map_size``
and the mesh's ``segments`` -- each set how much memory a frame takes. A size far beyond the
machine's memory would otherwise be found out after gigabytes had been allocated, as a
``MemoryError`` traceback or the kernel's out-of-memory kill. Each is refused when a frame
would take more than half the memory available now (:func:`available_memory`), in one line
naming the key, what it would take and the largest that fits.

The costs per element were measured with ``/usr/bin/time -f %M`` on ``jsss-render`` of
``examples/marble_sphere.toml`` (float32, 2026-12-04): from 640 x 480 to 1280 x 960 pixels
the peak resident memory grew by 1.0 KiB per pixel with Lambert, 1.25 KiB with texture space
and 1.6 KiB with image space; :data:`BYTES_PER_PIXEL` takes 2 KiB. A texel of the texture
holds one irradiance and its blurred copies per Gaussian and basis profile (8-16 of them, three
channels, and the blur's temporaries); :data:`BYTES_PER_TEXEL` takes 1 KiB. A shadow map's
texel is a depth and the rasteriser's temporaries (:data:`BYTES_PER_SHADOW_TEXEL`), a
triangle its vertices, raster and spectral-filter rows (:data:`BYTES_PER_TRIANGLE`).
"""

from __future__ import annotations

import os

__all__ = ["BYTES_PER_PIXEL", "BYTES_PER_SHADOW_TEXEL", "BYTES_PER_TEXEL", "BYTES_PER_TRIANGLE", "MAX_SAMPLES",
           "available_memory", "check_size", "describe_bytes"]

BYTES_PER_PIXEL = 2048
BYTES_PER_TEXEL = 1024
BYTES_PER_SHADOW_TEXEL = 64
BYTES_PER_TRIANGLE = 2048
MAX_SAMPLES = 65536  # image-space samples per pixel (the calibration measures 8 to 128)
FALLBACK_MEMORY = 8 << 30  # where the system does not say


def available_memory() -> int:
    """Bytes of memory available now: ``$JSSS_MEMORY_LIMIT`` (bytes) if set, else the system's
    available physical memory (``/proc/meminfo``'s MemAvailable, else ``sysconf``), else 8 GiB."""
    override = os.environ.get("JSSS_MEMORY_LIMIT")
    if override:
        try:
            return max(int(float(override)), 0)
        except ValueError:
            pass
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return FALLBACK_MEMORY


def describe_bytes(count: float) -> str:
    """``count`` bytes in the largest binary unit that keeps it above 1 (``1.5 GiB``)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(count) < 1024 or unit == "PiB":
            return f"{count:.3g} {unit}"
        count /= 1024
    return f"{count:.3g} PiB"


def check_size(elements: float, bytes_each: int, what: str, *, largest: str | None = None) -> str | None:
    """The problem with asking for ``elements`` of ``bytes_each`` bytes, or None when a frame fits
    in half the available memory. ``what`` names the request (``"640 x 480 pixels"``);
    ``largest`` formats the largest count that fits (default: a plain count)."""
    budget = available_memory() / 2
    need = float(elements) * bytes_each
    if need <= budget:
        return None
    fits = int(budget // bytes_each)
    limit = largest.format(fits) if largest is not None else f"{fits:,}"
    return (f"{what} would take about {describe_bytes(need)}; half the memory available now is "
            f"{describe_bytes(budget)} (at most {limit}).")
