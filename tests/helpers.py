"""Helpers shared by the tests: finite differences, quadrature on log grids, and a 16-bit PNG writer."""

from __future__ import annotations

import numpy as np


def central_difference(f, x, *, rel_step=1e-6):
    """Central difference of scalar ``f`` at scalar ``x`` with a step relative to ``|x|``."""
    h = rel_step * max(abs(float(x)), 1e-3)
    return (float(f(x + h)) - float(f(x - h))) / (2 * h)


def radial_integral(values_fn, r_min, r_max, *, n=40001):
    """``2 pi int r f(r) dr`` on a log grid by Simpson's rule (substituting r = e^t).

    ``values_fn`` maps an array of radii (N,) to values (N, ...). The part below
    ``r_min`` is added as ``pi r_min^2 f(r_min)`` (f is flat there for the profiles).
    """
    from scipy.integrate import simpson

    t = np.linspace(np.log(r_min), np.log(r_max), n)
    r = np.exp(t)
    f = np.asarray(values_fn(r))
    weights = (2 * np.pi * r**2).reshape((-1,) + (1,) * (f.ndim - 1))
    core = simpson(weights * f, x=t, axis=0)
    return core + np.pi * r_min**2 * f[0]


def fresnel_reflectance_numpy(cos_i, eta):
    """Unpolarised Fresnel reflectance written out in NumPy, apart from ``jsss.fresnel`` (a truth for tests)."""
    cos_i = np.asarray(cos_i, float)
    sin_t2 = (1 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.maximum(1 - sin_t2, 0.0))
    rs = (cos_i - eta * cos_t) / np.maximum(cos_i + eta * cos_t, 1e-300)
    rp = (eta * cos_i - cos_t) / np.maximum(eta * cos_i + cos_t, 1e-300)
    return np.where(sin_t2 >= 1, 1.0, 0.5 * (rs**2 + rp**2))


def external_diffuse_transmittance(eta):
    """int_0^1 (1 - F(mu, eta)) 2 mu dmu by adaptive quadrature: diffuse light from outside that enters."""
    from scipy.integrate import quad

    lower = np.sqrt(max(0.0, 1 - eta**2))
    return quad(lambda mu: (1 - fresnel_reflectance_numpy(mu, eta)) * 2 * mu, lower, 1, epsabs=1e-13, limit=200)[0]


def _paeth(left, up, up_left):
    """The PNG specification's Paeth predictor (section 9.4), elementwise on int arrays."""
    p = left + up - up_left
    pa, pb, pc = np.abs(p - left), np.abs(p - up), np.abs(p - up_left)
    return np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, up, up_left))


def png16(path, pixels, *, header=None):
    """A valid 16-bit RGB or RGBA PNG written by hand (Pillow writes none): IHDR, one IDAT, IEND.

    Row i uses filter type i mod 5 (None, Sub, Up, Average, Paeth; PNG specification section
    9.2), each encoded from the specification's formulas, so a reader that gets one wrong fails."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    height, width, planes = pixels.shape
    raw = pixels.astype(">u2").view(np.uint8).reshape(height, width * planes * 2).astype(np.int64)
    step = planes * 2  # bytes per pixel: the distance to "left"
    rows = []
    for i in range(height):
        x = raw[i]
        up = raw[i - 1] if i else np.zeros_like(x)
        left = np.concatenate([np.zeros(step, np.int64), x[:-step]])
        up_left = np.concatenate([np.zeros(step, np.int64), up[:-step]])
        kind = i % 5
        predicted = [0, left, up, (left + up) // 2, _paeth(left, up, up_left)][kind]
        rows.append(bytes([kind]) + ((x - predicted) % 256).astype(np.uint8).tobytes())
    colour = {3: 2, 4: 6}[planes]
    ihdr = header or struct.pack(">IIBBBBB", width, height, 16, colour, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"".join(rows)))
                     + chunk(b"IEND", b""))
    return path
