"""fit-params's fit on camera images at 0 and 40 degrees whose truth is an independent walk (issue 37).

Truth: :func:`measure.synth_transport.synthesize_walk` with its default camera, next-event
estimates toward the camera's exact direction from a NumPy walk that shares no code with the
transport tables (absorption in the walk, its own Fresnel and scattering code; see
:func:`measure.synth_transport.camera_walk`). Four media: marble (eta 1.5), skin1 and ketchup
(eta 1.3) from the library with g 0, and skin1's coefficients with g 0.9 (tissue's forward
scattering). Each image is 256 px on the sample plane, its half-field four diffusion lengths of
the medium's most penetrating channel, the beam one pixel wide (standard deviation), three
channels, 1.2e6 photons each. With 3e5 photons the images' own noise was near the target:
over seeds 21-26 marble's sigma_a at 0 degrees scattered by 1.2-1.8 % (standard deviation)
from walk to walk, two to three times the data's share of its stated error, because a walk
photon's next-event estimates land on many pixels along its path and so are correlated
across bins, which a camera's photon noise is not (2026-12-06). Fit:
:func:`measure.pipeline.fit_measurement` as ``fit-params`` runs it, model transport, the image's
view angle and g given (``--view-angle``, ``--g``), everything else default.

Per channel: relative error and z = (estimate - truth) / stated error of sigma_a and
sigma_s', chi^2/dof (the data's noise alone, and with the tables' own noise counted, which the
fit's quality judges: :attr:`fitting.medium.MediumFit.chi2_reduced_tables`) and the fit's
quality. The issue's target: every parameter within 3 %; ketchup's green and blue (reduced albedo 0.07 and 0.02: their light is single scattering in
the beam's core) may instead be within 3 stated errors. Walks take minutes (marble's red,
albedo' 0.999, longest), so ``--cache DIR`` keeps each image.

Run: ``python benchmarks/camera_angles.py [--cache DIR] [--photons N] [--out docs/benchmarks/camera_angles.md]``
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np

from jsss import hankel
from jsss.materials import material
from measure.pipeline import fit_measurement
from measure.synth_transport import synthesize_walk

sys.path.insert(0, os.path.dirname(__file__))
from measurement_transport import cached_image  # noqa: E402

VIEWS = (0.0, 40.0)
SIZE = 256
LOOSE = {("ketchup", 1), ("ketchup", 2)}  # (medium, channel) judged by z alone: the exception


def _media():
    skin = material("skin1")
    return {"marble": (material("marble"), 0.0), "skin1": (skin, 0.0), "ketchup": (material("ketchup"), 0.0),
            "skin1, g 0.9": (skin, 0.9)}


def _pixel_mm(medium):
    sigma_a, sigma_s_prime = np.asarray(medium.sigma_a, float), np.asarray(medium.sigma_s_prime, float)
    diffusion_length = 1 / np.sqrt(3 * sigma_a * (sigma_a + sigma_s_prime))
    return float(4 * diffusion_length.max() / (SIZE / 2))


def _image(name, medium, g, view, *, photons, seed, cache):
    pixel_mm = _pixel_mm(medium)
    path = None
    if cache:
        os.makedirs(cache, exist_ok=True)
        path = os.path.join(cache, f"{name.replace(', ', '_').replace(' ', '')}_view{view:g}_p{photons}_s{seed}.npz")
    return cached_image(path, lambda: synthesize_walk(medium, g=g, photons=photons, pixel_mm=pixel_mm, size=SIZE,
                                                      beam_sigma_mm=pixel_mm, view_deg=view, seed=seed))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--photons", type=int, default=1_200_000, help="photons per channel and image")
    parser.add_argument("--seed", type=int, default=21)
    parser.add_argument("--cache", default=None, help="directory that keeps the walk images between runs")
    parser.add_argument("--media", nargs="+", default=None, help="a subset of: " + ", ".join(_media()))
    parser.add_argument("--out", default=None, help="also write the table to this markdown file")
    args = parser.parse_args()
    media = {k: v for k, v in _media().items() if args.media is None or k in args.media}
    grid = hankel.hankel_grid()
    lines = [f"# Camera fits at 0 and 40 degrees ({datetime.date.today().isoformat()})", "",
             ("Truth: images from an independent walk (`measure.synth_transport.camera_walk`: next-event estimates "
              "toward the camera's exact direction, no code shared with the transport tables), "
              f"{args.photons:.1e} photons per channel, {SIZE} px over 4 diffusion lengths each side, seed {args.seed}. "
              "Fit: `fit_measurement(model='transport', g=..., view_angle_deg=...)`, other settings default. "
              "Written by `benchmarks/camera_angles.py`."), "",
             ("| medium | view | channel | sigma_a error (z) | sigma_s' error (z) | chi2/dof | chi2/dof, tables counted "
              "| quality | meets target |"),
             "|---|---:|---|---:|---:|---:|---:|---|---|"]
    print("\n".join(lines), flush=True)
    met, total = 0, 0
    for name, (medium, g) in media.items():
        for view in VIEWS:
            image, walk_s = _image(name, medium, g, view, photons=args.photons, seed=args.seed, cache=args.cache)
            fit = fit_measurement(image.measurement, image.reference, _pixel_mm(medium), float(np.max(medium.eta)),
                                  model="transport", g=g, view_angle_deg=view, grid=grid)
            table = fit.table()
            for c, channel in enumerate("RGB"):
                cells, within = [], []
                for key in ("sigma_a", "sigma_s_prime"):
                    true = float(np.asarray(getattr(medium, key))[c])
                    value = table[key][c]
                    err = table[f"{key}_err"][c]
                    rel, z = value / true - 1, (value - true) / err if err else np.nan
                    cells.append(f"{rel:+.1%} ({z:+.1f})")
                    within.append(abs(z) <= 3 if (name, c) in LOOSE else abs(rel) <= 0.03)
                total += 1
                met += all(within)
                row = (f"| {name} | {view:g} | {channel} | {cells[0]} | {cells[1]} | {table['chi2_reduced'][c]:.3g} | "
                       f"{table['chi2_reduced_tables'][c]:.3g} | {table['quality'][c].split(':')[0]} | "
                       f"{'yes' if all(within) else 'no'} |")
                lines.append(row)
                print(row, flush=True)
            print(f"<!-- {name} {view:g} deg: walk {walk_s:.0f} s -->", file=sys.stderr, flush=True)
    lines += ["", f"{met} of {total} channels meet the target (within 3 % each; ketchup G/B within 3 stated errors)."]
    print(lines[-1])
    if args.out:
        with open(args.out + ".tmp", "w") as handle:
            handle.write("\n".join(lines) + "\n")
        os.replace(args.out + ".tmp", args.out)


if __name__ == "__main__":
    main()
