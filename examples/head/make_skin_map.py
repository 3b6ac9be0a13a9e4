"""Writes ``skin_albedo.png``, the head's skin colour map (the recipe; the file is committed).

The scan's colour photograph is not ours to redistribute, so the colour comes from physiology:
a map of melanin and one of blood over the surface, turned into colour by the same three-layer
skin that renders the head (:func:`jsss.layers.skin_three_layer`: oil film, epidermis, dermis).

1. **Where the pigments are.** Each texel's 3D position on the head (:func:`jsss.render.texture_space.bake_texels`)
   sets two volume fractions:

   * melanin in the epidermis, ``M = 0.012 (1 + 0.35 n_1)`` plus freckles, ``0.03 min(1, max(0, n_2 - 0.3) / 0.3)``
     where ``n_2`` is fine noise, strongest across the nose and cheeks;
   * blood in the dermis, ``B = 0.005 (1 + 0.25 n_3)`` times ``1 + 2.5 g_cheeks + 2.0 g_nose + 6.0 g_lips +
     1.5 g_ears``, where each ``g`` is a Gaussian about a landmark found on the mesh (the nose tip is
     its foremost point; the ears its outermost at eye height; cheeks and lips sit at fixed offsets
     from the nose tip);

   and ``n_i`` are fractal value noises in [-1, 1] of the 3D position, so the map has no seams.
2. **Absorption**, at 650 / 550 / 450 nm for R / G / B (band centres, not integrated over a camera's
   bands), in 1/mm:

   * epidermis: ``M sigma_mel + (1 - M) sigma_base``, with eumelanin
     ``sigma_mel = 6.6e11 lambda^-3.33 /cm`` and the bloodless baseline
     ``sigma_base = 0.244 + 85.3 exp(-(lambda - 154) / 66.2) /cm`` (Jacques 1998, "Skin optics",
     Oregon Medical Laser Center News);
   * dermis: ``B sigma_blood + (1 - B) sigma_base``, blood of 150 g/l haemoglobin (64 500 g/mol) at
     75 % oxygen saturation, from Prahl's molar extinction coefficients (omlc.org/spectra/hemoglobin:
     HbO2 368 / 43016 / 62816, Hb 3750 / 53412 / 103292 /cm/M at 650 / 550 / 450 nm), times ln 10.
3. **Colour.** Scattering and thicknesses are the preset's. The stack's total diffuse reflectance
   (:func:`jsss.layers.stack_spectra` at k = 0) on a 24 x 24 grid of (M, B), interpolated per texel,
   is the colour map; the scene normalises its profile (``normalize_profile = true``), so the map
   alone sets the colour and the profile the spread, as d'Eon et al. 2007 (sec. 5.3) do with a photo.
   Texels outside the UV islands take their nearest island texel's colour, so filtering at an
   island's edge does not pull in black.

Run: ``python examples/head/make_skin_map.py`` (about 10 s).
"""

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", ".."))

SIZE = 512
WAVELENGTHS = np.array([650.0, 550.0, 450.0])  # nm: R, G, B


def melanin_absorption():
    return 6.6e11 * WAVELENGTHS ** -3.33 / 10.0  # 1/cm -> 1/mm


def baseline_absorption():
    return (0.244 + 85.3 * np.exp(-(WAVELENGTHS - 154.0) / 66.2)) / 10.0


def blood_absorption(saturation=0.75, grams_per_litre=150.0, molar_mass=64500.0):
    oxy = np.array([368.0, 43016.0, 62816.0])  # cm^-1 / (mol / l), Prahl
    deoxy = np.array([3750.12, 53412.0, 103292.0])
    extinction = saturation * oxy + (1 - saturation) * deoxy
    return np.log(10.0) * extinction * grams_per_litre / molar_mass / 10.0


def value_noise_3d(points, cell, seed):
    """Smooth noise in [-1, 1] of 3D points [mm] on a lattice of ``cell`` mm (trilinear, smoothstep)."""
    rng = np.random.default_rng(seed)
    lattice = rng.uniform(-1, 1, size=(64, 64, 64))
    x = points / cell + 32.0
    base = np.floor(x).astype(int)
    f = x - base
    f = f * f * (3 - 2 * f)
    total = 0.0
    for corner in np.ndindex(2, 2, 2):
        weight = np.prod(np.where(np.array(corner), f, 1 - f), axis=-1)
        i = (base + np.array(corner)) % 64
        total = total + weight * lattice[i[..., 0], i[..., 1], i[..., 2]]
    return total


def fractal_noise(points, cell, seed, octaves=4):
    total, amplitude, norm = 0.0, 1.0, 0.0
    for octave in range(octaves):
        total = total + amplitude * value_noise_3d(points, cell / 2**octave, seed + octave)
        norm += amplitude
        amplitude *= 0.5
    return total / norm


def gaussian(points, centre, sigma):
    return np.exp(-0.5 * np.sum(((points - centre) / sigma) ** 2, axis=-1))


def landmarks(vertices):
    """Nose tip, cheeks, lips and ears [mm] of a head facing -y with +z up."""
    head = vertices[vertices[:, 2] > vertices[:, 2].max() - 260.0]  # above the shoulders
    nose = head[np.argmin(head[:, 1])]
    eye_height = head[np.abs(head[:, 2] - (nose[2] + 30.0)) < 25.0]
    ears = [eye_height[np.argmax(side * eye_height[:, 0])] - np.array([side * 8.0, 0.0, 0.0]) for side in (-1, 1)]
    cheeks = [nose + np.array([side * 42.0, 30.0, -8.0]) for side in (-1, 1)]
    lips = nose + np.array([0.0, 14.0, -36.0])
    return nose, cheeks, lips, ears


def pigments(points, facing_front, vertices):
    nose, cheeks, lips, ears = landmarks(vertices)
    face = sum(gaussian(points, c, 22.0) for c in cheeks) + gaussian(points, nose, 14.0)
    freckles = 0.03 * np.clip((fractal_noise(points, 2.0, 11, octaves=2) - 0.3) / 0.3, 0, 1)
    melanin = 0.012 * (1 + 0.35 * fractal_noise(points, 30.0, 1)) + freckles * np.clip(face, 0, 1) * facing_front
    flush = (1 + 2.5 * sum(gaussian(points, c, 20.0) for c in cheeks) + 2.0 * gaussian(points, nose, 12.0)
             + 6.0 * gaussian(points, lips, np.array([16.0, 10.0, 7.0])) + 1.5 * sum(gaussian(points, e, 22.0) for e in ears))
    blood = 0.005 * (1 + 0.25 * fractal_noise(points, 8.0, 5)) * flush
    lips_weight = gaussian(points, lips, np.array([16.0, 10.0, 7.0]))
    melanin = melanin * (1 - 0.6 * lips_weight)  # the lips' thin epidermis
    return np.clip(melanin, 0.002, 0.2), np.clip(blood, 0.001, 0.08)


def reflectance_table(melanin, blood):
    """Total diffuse reflectance (RGB) of the skin stack for each (melanin, blood) pair."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from jsss.layers import Layer, skin_three_layer, stack_spectra
    from jsss.medium import Medium

    (oil, epidermis), dermis = skin_three_layer(dtype=np.float64)
    m, b = np.meshgrid(melanin, blood, indexing="ij")
    m, b = m.reshape(-1, 1), b.reshape(-1, 1)
    ones = np.ones((m.size, 3))

    def tiled(x):
        return (ones * np.asarray(x)).reshape(-1)

    epidermis_a = m * melanin_absorption() + (1 - m) * baseline_absorption()
    dermis_a = b * blood_absorption() + (1 - b) * baseline_absorption()
    layers = [Layer(Medium(tiled(oil.medium.sigma_a), tiled(oil.medium.sigma_s_prime), tiled(oil.medium.eta)), oil.thickness),
              Layer(Medium(epidermis_a.reshape(-1), tiled(epidermis.medium.sigma_s_prime), tiled(epidermis.medium.eta)),
                    epidermis.thickness)]
    base = Medium(dermis_a.reshape(-1), tiled(dermis.sigma_s_prime), tiled(dermis.eta))
    R = np.asarray(stack_spectra(layers, base, 0.0)[0])
    return R.reshape(len(melanin), len(blood), 3)


def main(out=None):
    out = out or os.path.join(HERE, "skin_albedo.png")
    import imageio.v3 as iio
    from scipy.interpolate import RegularGridInterpolator
    from scipy.ndimage import distance_transform_edt

    from jsss.render.mesh import load_mesh
    from jsss.render.surface_maps import srgb_to_linear  # noqa: F401 (the map is read back through it)
    from jsss.render.texture_space import bake_texels

    mesh, _ = load_mesh(os.path.join(HERE, "head.obj"))
    mesh = type(mesh)(mesh.vertices * 1000.0, mesh.normals, mesh.uvs, mesh.faces, name="head")  # m -> mm
    texels = bake_texels(mesh, SIZE)
    mask = np.asarray(texels.mask)
    points = np.asarray(texels.position)[mask]
    facing_front = np.clip(-np.asarray(texels.normal)[mask][:, 1], 0, 1)
    melanin, blood = pigments(points, facing_front, mesh.vertices)

    grid_m, grid_b = np.geomspace(0.002, 0.2, 24), np.geomspace(0.001, 0.08, 24)
    table = reflectance_table(grid_m, grid_b)
    interpolate = RegularGridInterpolator((np.log(grid_m), np.log(grid_b)), table)
    colour = np.zeros((SIZE, SIZE, 3))
    colour[mask] = interpolate(np.stack([np.log(melanin), np.log(blood)], -1))
    _, (rows, cols) = distance_transform_edt(~mask, return_indices=True)  # fill outside the islands
    colour = colour[rows, cols]

    srgb = np.where(colour <= 0.0031308, 12.92 * colour, 1.055 * np.clip(colour, 0, 1) ** (1 / 2.4) - 0.055)
    image = np.round(np.clip(srgb, 0, 1) * 255).astype(np.uint8)[::-1]  # texel rows run up v; images down
    iio.imwrite(out, image)
    print(f"{out}: {SIZE} x {SIZE}; linear colour over the skin: mean {colour[mask].mean(0).round(3)}, "
          f"range {colour[mask].min(0).round(3)} - {colour[mask].max(0).round(3)}")


if __name__ == "__main__":
    main()
