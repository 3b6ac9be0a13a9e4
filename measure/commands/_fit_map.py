"""``jsss-render fit --albedo-map``: a colour map and the mean free path from a photo.

The command's other half (:mod:`measure.commands.render` parses the flags, reads the photo and
resolves the exposure); this one checks what the map fit cannot take, runs
:func:`fitting.albedo_map.fit_albedo_map` and writes its files:

* ``PHOTO.albedo.exr``: the fitted colour map, linear, in the map files' orientation (the
  file's bottom row is v = 0, as ``[material.maps]`` reads it);
* ``PHOTO.albedo_err.exr``: each texel's standard error; texels the camera does not see are
  infinite (they keep the start, the seen texels' median, in the map);
* ``PHOTO.fit.toml``: the scene with the fitted medium, ``texturing = "pre-post"`` and
  ``[material.maps] albedo`` naming the map, which ``jsss-render`` renders as it is;
* ``PHOTO.fit.json``: the mean free path and medium with errors, the map's counts and error
  quantiles, chi^2/dof, warnings and history;
* ``PHOTO.fit.png``: photo, fit and whitened residual;
* with ``--export mitsuba`` / ``blender``: the material for that renderer with the map as its
  texture (``PHOTO.fit_mitsuba.xml`` and ``PHOTO.fit_mitsuba_transmittance.exr``,
  ``PHOTO.fit_blender.py`` and ``PHOTO.fit_blender_colour.exr``; :mod:`measure.export`'s
  "Colour maps"), when the fit converged.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import tomlkit

from ._console import UsageError, json_safe, write_fit_files
from ._scene_files import MAP_EXPORTS


def map_size(text: str) -> int | None:
    """``--albedo-map``'s value: ``auto`` (None) or a texel count per side (exit 2 otherwise)."""
    if text == "auto":
        return None
    try:
        size = int(text)
    except ValueError:
        size = 0
    if size < 2:
        raise UsageError(f"--albedo-map must be 'auto' or the map's texels per side (an integer >= 2); got {text}")
    return size


def check_flags(args) -> None:
    """The fit flags a map fit does not take, named (exit 2)."""
    refused = [(args.fit_gain, "--fit-gain", ("the map's scale and the gain are one direction: give the exposure "
                                               "(--reference-scene CARD.toml, --gain G or --no-gain)")),
               (args.highlight in ("fit", "mask"), f"--highlight {args.highlight}",
                ("the map fit models the highlight at the scene's roughness: fit it first (jsss-render fit without "
                 "--albedo-map) and put the roughness in the scene, or --no-specular for a photo of subsurface "
                 "light only")),
               (args.method not in ("auto", "texture-space"), f"--method {args.method}",
                "a map is fitted in texture space (the renderer's texels carry it)"),
               (args.rim_mm != 0, "--rim-mm", "leave the rim out with --mask instead"),
               ("pbrt" in (args.export or []), "--export pbrt",
                f"pbrt's subsurface material is written without a texture; export {' or '.join(MAP_EXPORTS)}")]
    for on, flag, why in refused:
        if on:
            raise UsageError(f"{flag} does not go with --albedo-map: {why}")


def fit_map(args, scene, photo, mask, noise, gain, gain_err, exposure, say) -> int:
    """Run the map fit and write its files; returns the exit status (0, or 1 if not converged)."""
    from fitting.albedo_map import fit_albedo_map
    from measure.exr import write_exr

    from ._scene_files import export_material, fitted_material, scene_with_material

    material = scene.material
    if args.profile is not None or args.g is not None:
        material = dataclasses.replace(material, profile_model=args.profile or material.profile_model,
                                       g=material.g if args.g is None else args.g, profile=None)
        scene = dataclasses.replace(scene, material=material)
    t0 = time.perf_counter()
    model_error = {} if args.model_error is None else {"model_error": args.model_error}
    fit = fit_albedo_map(scene, photo, gain=gain, gain_err=gain_err, noise=noise, loss=args.loss, mask=mask, **model_error,
                         saturation=args.saturation, map_size=map_size(args.albedo_map), accuracy=args.accuracy,
                         specular=not args.no_specular, progress=lambda line: say(f"{args.scene}: {line}"))
    seconds = time.perf_counter() - t0
    out = Path(args.output)
    stem = Path(args.photo).name.rsplit(".", 1)[0]
    map_path, err_path = out / f"{stem}.albedo.exr", out / f"{stem}.albedo_err.exr"
    # The map's rows increase with v; a map file's bottom row is v = 0 (surface_maps.read_map)
    write_exr(map_path, fit.albedo[::-1].astype(np.float32))
    write_exr(err_path, fit.albedo_err[::-1].astype(np.float32))
    seen = fit.seen
    relative = (fit.albedo_err / fit.albedo)[seen] if seen.any() else np.full((0, 3), np.inf)
    profile = fit.profile_model
    summary = {
        "scene": str(args.scene), "photo": str(args.photo), "seconds": round(seconds, 3), "exposure": exposure,
        "kind": "albedo map", "map": map_path.name, "map_err": err_path.name,
        "map_size": list(fit.albedo.shape[:2]), "texels_seen": int(seen.sum()),
        "map_relative_err_median": np.median(relative, axis=0).tolist() if relative.size else None,
        "map_relative_err_p90": np.percentile(relative, 90, axis=0).tolist() if relative.size else None,
        "mean_free_path_mm": fit.mean_free_path.tolist(), "mean_free_path_err_mm": fit.mean_free_path_err.tolist(),
        "sigma_a": np.asarray(fit.medium.sigma_a).tolist(), "sigma_s_prime": np.asarray(fit.medium.sigma_s_prime).tolist(),
        "eta": np.broadcast_to(np.asarray(fit.medium.eta, float), (3,)).tolist(),
        "profile_model": profile, "loss": args.loss, "model_error": fit.model_error, "chi2_reduced": fit.chi2_reduced,
        "converged": fit.converged,
        "steps": fit.steps, "cg_steps": fit.cg_steps, "errors": fit.errors,
        "warnings": list(fit.warnings), "history": list(fit.history)}
    fitted = fitted_material(fit.medium, profile=profile, g=scene.material.g, roughness=material.roughness,
                             specular=material.specular,
                             comment=f"fitted by jsss-render fit --albedo-map ({profile} profile, texture-space); "
                                     "errors in the .fit.json and the .albedo_err.exr")
    fitted.add("texturing", "pre-post")
    fitted.add("maps", tomlkit.table().add("albedo", map_path.name))
    written = write_fit_files(args, stem, json_safe(summary), scene_with_material(Path(args.scene).read_text(), fitted),
                              lambda tmp: _figure(photo, fit, tmp), fit.warnings)
    if not args.json:
        print(f"fitted {args.photo}: a {fit.albedo.shape[1]} x {fit.albedo.shape[0]} colour map ({int(seen.sum())} "
              f"texels seen) and the mean free path ({profile} profile, {fit.steps} steps, {seconds:.1f} s, "
              f"chi2/dof {fit.chi2_reduced:.2f})")
        print(f"  {'mean free path [mm]':<24}" + "  ".join(f"{v:.5g} +- {e:.2g}" for v, e in
                                                       zip(fit.mean_free_path, fit.mean_free_path_err)))
        if relative.size:
            print(f"  {'map error, median':<24}" + "  ".join(f"{100 * v:.2g} %" for v in np.median(relative, axis=0)))
        print(f"  {'gain':<24}{exposure}")
    if args.export and not fit.converged:
        print(f"{args.prog}: warning: no material exported: the map fit did not converge", file=sys.stderr)
    elif args.export:
        written += [path for _, path in export_material(args.export, out / f"{stem}.fit", fit.medium,
                                                        g=scene.material.g, unit_mm=args.unit_mm,
                                                        albedo_map=fit.albedo)]
    print("wrote " + ", ".join(str(p) for p in [map_path, err_path, *written]),
          file=sys.stderr if args.json else sys.stdout)
    if not fit.converged:
        print(f"{args.prog}: error: the map fit did not converge (see the history in the .fit.json); the map is not "
              "a measurement", file=sys.stderr)
        return 1
    return 0


def _figure(photo, fit, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jsss.render.shading import tone_map

    shown, exposure = tone_map(photo)
    image, _ = tone_map(fit.image, exposure=exposure)
    mask, sigma = fit.masks[0], fit.sigma[0]
    residual = np.where(mask, ((fit.image - photo) / sigma).mean(-1) * np.sqrt(3), np.nan)
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.6), constrained_layout=True)
    axes[0].imshow(shown)
    axes[0].set_title("photo")
    axes[1].imshow(image)
    axes[1].set_title("fit (texture space, the fitted map)")
    im = axes[2].imshow(residual, cmap="RdBu_r", vmin=-4, vmax=4)
    axes[2].set_title("(fit - photo) / noise, fitted pixels")
    fig.colorbar(im, ax=axes[2], shrink=0.85)
    shown_map = np.where(fit.seen[..., None], np.clip(fit.albedo, 0, 1), 0.5)[::-1] ** (1 / 2.2)
    axes[3].imshow(shown_map)
    axes[3].set_title("colour map (grey: unseen)")
    for ax in axes:
        ax.set_axis_off()
    fig.savefig(path, dpi=110, format="png")  # the path may be a temporary name without a suffix
    plt.close(fig)
