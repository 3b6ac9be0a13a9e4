"""Writes the example scenes' maps (run from anywhere; the files are committed, this is their recipe).

* ``marble_veins.png``: a colour map for the marble sphere (``u`` is longitude, so the map
  wraps in ``u``): veins from ``sin`` of a turbulent phase (Perlin's classic marble, 1985) over
  fractal value noise, white stone (0.95, 0.93, 0.90) blended to grey-green veins
  (0.30, 0.36, 0.33), written as 8-bit sRGB.
* ``checker_sigma_a.exr``: a 4 x 4 checker of two absorptions for the checker plane (Mertens
  et al. 2003's experiment): marble's sigma_a and ketchup-like (0.06, 0.25, 0.4) 1/mm, linear.
* ``studio.exr``: a latitude-longitude environment, 128 x 256, linear half floats:
  :func:`jsss.render.environment.procedural_map` ``"studio"`` (a dim room, a large soft key
  front left, a small warm rim light behind).
"""

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", ".."))

from measure.exr import write_exr  # noqa: E402


def value_noise(shape, cells, rng):
    """Smooth noise in [0, 1), periodic in both axes, on a grid of ``cells`` (rows, columns)."""
    lattice = rng.uniform(size=cells)
    y = np.linspace(0, cells[0], shape[0], endpoint=False)
    x = np.linspace(0, cells[1], shape[1], endpoint=False)
    y0, x0 = np.floor(y).astype(int), np.floor(x).astype(int)
    fy, fx = y - y0, x - x0
    fy, fx = fy * fy * (3 - 2 * fy), fx * fx * (3 - 2 * fx)  # smoothstep
    y1, x1 = (y0 + 1) % cells[0], (x0 + 1) % cells[1]
    top = lattice[y0][:, x0] * (1 - fx) + lattice[y0][:, x1] * fx
    bottom = lattice[y1][:, x0] * (1 - fx) + lattice[y1][:, x1] * fx
    return top * (1 - fy)[:, None] + bottom * fy[:, None]


def marble_veins(height=256, width=512, seed=7):
    rng = np.random.default_rng(seed)
    turbulence = sum(value_noise((height, width), (4 * 2**o, 8 * 2**o), rng) / 2**o for o in range(5))
    v, u = np.meshgrid(np.linspace(0, 1, height), np.linspace(0, 1, width, endpoint=False), indexing="ij")
    phase = 2 * np.pi * (3 * u + 1.5 * v) + 5.0 * turbulence
    vein = (1 - np.abs(np.sin(phase))) ** 6  # thin dark lines where the phase crosses pi k
    stone, dark = np.array([0.95, 0.93, 0.90]), np.array([0.30, 0.36, 0.33])
    linear = stone * (1 - vein[..., None]) + dark * vein[..., None]
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def checker_sigma_a(size=256, squares=4):
    i = (np.arange(size) * squares // size)
    odd = (i[:, None] + i[None, :]) % 2 == 1
    return np.where(odd[..., None], [0.06, 0.25, 0.4], [0.0021, 0.0041, 0.0071])


if __name__ == "__main__":
    import imageio.v3 as iio

    iio.imwrite(os.path.join(HERE, "marble_veins.png"), marble_veins())
    write_exr(os.path.join(HERE, "checker_sigma_a.exr"), checker_sigma_a())
    from jsss.render.environment import procedural_map

    write_exr(os.path.join(HERE, "studio.exr"), procedural_map("studio", (128, 256)).astype(np.float32),
              pixel_type="half")
    print("wrote marble_veins.png, checker_sigma_a.exr and studio.exr in", HERE)
