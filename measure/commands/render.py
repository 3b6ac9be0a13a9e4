"""``jsss-render``: render TOML scenes to PNG (display) and EXR (linear radiance); ``jsss-render
fit``: a material from a photo of an object whose scene (geometry, camera, lights) is known.

Examples
--------
::

    jsss-render examples/marble_sphere.toml -o marble.png --plan --timings
    jsss-render examples/ketchup_plane.toml --method image-space --samples 64
    jsss-render examples/*.toml -o renders/
    jsss-render fit examples/marble_sphere.toml photo.exr -o fitted/
    jsss-render fit scene.toml photo.exr --json --profile transport --mask mask.png

The renderer is :mod:`jsss.render`, the fit :func:`fitting.fit_render`; the command lives
here, above both in the dependency order, because it reads photos and writes images.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import traceback
from pathlib import Path

from ._console import (
    Parser,
    Progress,
    UsageError,
    add_commands,
    error_line,
    exit_status,
    json_safe,
    start,
    version,
    write_fit_files,
    write_png,
)
from ._scene_files import EXPORTS

__all__ = ["main", "parser"]

PROG = "jsss-render"

_EPILOG = """\
examples:
  jsss-render examples/marble_sphere.toml -o marble.png --plan --timings
  jsss-render examples/ketchup_plane.toml --method image-space --samples 64
  jsss-render examples/*.toml -o renders/       (several scenes: -o is a directory)
  jsss-render example:head                       (a scene shipped with jsss, from any folder; example:list)
  jsss-render fit scene.toml photo.exr --gain 1 (fit the material to a photo: jsss-render fit --help)

The scene format (geometry, material, lights, camera, render) is described in the docs,
docs/guides/scene_format.md. A scene that fails is reported in one line; the others still
render and the exit status is 2.
"""

_FIT_EPILOG = """\
The photo is linear (EXR, 16-bit TIFF/PNG or camera raw) at the scene camera's resolution;
pixels are proportional to the radiance toward the camera. The scene's material gives eta,
the surface roughness and the starting guess of sigma_a and sigma_s'. Pixels used: the object
as the camera sees it, without silhouette and grazing pixels, without saturated pixels
(--saturation) and where --mask is non-zero. Writes PHOTO.fit.json (the parameters with
standard errors, the artist's reflectance and mean free path, the covariance, warnings),
PHOTO.fit.toml (the scene with the fitted material, which jsss-render renders as it is; the
rest of the scene file is kept, comments included) and PHOTO.fit.png (photo, fit and whitened
residual side by side). The standard errors hold the photo's noise (estimated from it) and the
renderer's own error, 1.5 % of each channel's light (--model-error). Exit status 2 on bad input
(one line).

A photo taken through the surface holds the specular highlight, whose pixels would steer the
fit if the scene's roughness were wrong: --highlight fit fits the roughness (the default where
the highlight is in view under point or directional lights), --highlight mask leaves its pixels
out, --highlight model holds it at the scene's roughness. The table and JSON say which was done.

The photo's exposure must come from somewhere, since its brightness is gain x R_d:
* a white or grey target of known reflectance, photographed with the same camera and light
  (flags: --reference-scene CARD.toml [--reference-photo REF.exr] [--reference-reflectance]), in
  the photo itself (CARD.toml places the card; --reference-mask marks its pixels) or in a
  photo of its own; the gain and its error enter the fit;
* the camera's word: --gain G [--gain-err E], or --no-gain (G = 1: calibrated radiance);
* --fit-gain: fit it; unless the photo pins it (its error under 5 %), R_d, sigma_a and the
  gain then have no finite error, converged is false, and the exit status is 1.
Example, a grey card of 18 % photographed beside the sample:
  jsss-render fit sphere.toml photo.exr --reference-scene card.toml --reference-reflectance 0.18
Exit status 1 where the exposure is unresolved.

A painted or textured object: --albedo-map [SIZE] fits a colour map (pre-post, d'Eon 2007
sec. 5.3) and one mean free path per channel, the scene's reduced albedo held (the map carries
the colour). It writes PHOTO.albedo.exr and PHOTO.albedo_err.exr (unseen texels: infinite
error) and a PHOTO.fit.toml whose [material.maps] names the map. The exposure is required; the
highlight is modelled at the scene's roughness. See docs/guides/albedo_maps.md.
  jsss-render fit plane.toml photo.exr --no-gain --albedo-map 64
Exit status 1 where the map fit did not converge.
"""

_DESCRIPTION = ("Render TOML scenes of translucent objects to a PNG (display) and an EXR (linear radiance), planning "
                "the passes each scene needs. Also: 'jsss-render fit ...' fits a material to a photo.")


# ----------------------------------------------------------------------------- command line
def _methods() -> tuple[str, ...]:
    from jsss.render.passes import Method

    return tuple(m.option for m in Method)


def _render_options(methods) -> argparse.ArgumentParser:
    options = argparse.ArgumentParser(add_help=False)
    options.add_argument("-o", "--output", default=None,
                         help="PNG to write (default: the scene's name .png); with several scenes a directory. The "
                              "linear EXR goes beside each PNG")
    options.add_argument("--plan", action="store_true", help="print which passes run and why")
    options.add_argument("--timings", action="store_true", help="time each pass (compiles first, median of 3)")
    options.add_argument("--accuracy", type=float, default=None, help="override the scene's accuracy target")
    options.add_argument("--method", default="auto", choices=("auto", *methods),
                         help="how to render subsurface light (default: the planner's choice from its calibration "
                              "table)")
    options.add_argument("--samples", type=int, default=None, help="image-space samples per pixel")
    options.add_argument("--normal-filter", default="spectral", choices=("spectral", "naive"),
                         help="which Patro filter --method normal-filtering uses")
    options.add_argument("--float64", action="store_true", help="render in float64 (default float32)")
    options.add_argument("--allow-outside-paths", action="store_true",
                         help="let a scene name files (OBJ, maps) outside its own folder")
    options.add_argument("--no-exr", action="store_true", help="write only the PNG")
    options.add_argument("-q", "--quiet", action="store_true",
                         help="no progress lines (they go to stderr, and only when it is a terminal)")
    options.add_argument("--version", action="version", version=version(PROG))
    return options


def parser() -> argparse.ArgumentParser:
    """The ``jsss-render`` parser: rendering scenes (the default command) and the ``fit`` subcommand."""
    methods = _methods()
    options = _render_options(methods)
    formatting = dict(epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter, description=_DESCRIPTION)
    scenes = Parser(prog=PROG, parents=[options], **formatting)
    scenes.add_argument("scenes", nargs="+", metavar="scene",
                        help="TOML scene file(s), or example:NAME for a scene shipped with jsss (example:list)")
    top = Parser(prog=PROG, parents=[options], **formatting)
    top.set_defaults(run=_render, prog=PROG)
    commands = add_commands(top, default=scenes, dest="command", required=True, metavar="scene ... | fit",
                            help="TOML scene file(s) (see examples/); or the subcommand:")
    _fit_parser(commands, methods)
    return top


def _fit_parser(commands, methods):
    p = commands.add_parser("fit", epilog=_FIT_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
                            help="fit a scene's material to a photo of it (jsss-render fit --help)",
                            description="Fit sigma_a and sigma_s' per channel (and an exposure gain) of a scene's "
                                        "homogeneous material to a linear HDR photo of it, by inverse rendering.")
    p.add_argument("scene", help="TOML scene file: geometry, camera and lights as photographed")
    p.add_argument("photo", help="linear HDR photo (EXR, 16-bit TIFF/PNG, raw) at the camera's resolution")
    p.add_argument("-o", "--output", default=".", help="directory for the .fit.json/.toml/.png (default: here)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    p.add_argument("--mask", default=None, help="image of the camera's size; pixels where it is 0 are not fitted")
    p.add_argument("--saturation", type=float, default=None,
                   help="pixel value at which the camera clipped; pixels at or above it are not fitted")
    p.add_argument("--noise", default="estimate",
                   help="each pixel's noise: 'estimate' (default: read, shot and relative noise fitted to the "
                        "residuals of a first fit) or a relative error, e.g. 0.01")
    p.add_argument("--loss", choices=("huber", "squared"), default="huber",
                   help="huber (default: pixels beyond 1.345 errors count linearly, so fireflies and hot pixels "
                        "do not steer the fit) or squared (plain least squares)")
    p.add_argument("--profile", choices=("dipole", "transport"), default=None,
                   help="profile model (default: the scene's; transport is exact to radiative transfer)")
    p.add_argument("--g", type=float, default=None, help="Henyey-Greenstein g of the transport profile")
    p.add_argument("--method", default="auto", choices=("auto", *methods),
                   help="render method during the fit (default: the planner's choice for --accuracy)")
    p.add_argument("--accuracy", type=float, default=0.001,
                   help="accuracy target of the fit's renders (default 0.001: a fit needs a stricter render than "
                        "a display does)")
    p.add_argument("--model-error", type=float, default=None, metavar="E",
                   help="the renderer's relative error in each channel's light, carried into the stated errors "
                        "beside the photo's noise (default 0.015: its frames against a path tracer; 0: noise only)")
    exposure = p.add_argument_group("the photo's exposure (one of these is required; see below)")
    exposure.add_argument("--reference-scene", metavar="CARD.toml",
                          help="scene of a white or grey Lambertian target as photographed (same camera and lights)")
    exposure.add_argument("--reference-photo", metavar="REF.exr",
                          help="the target's photo (default: the photo being fitted, the card in its frame)")
    exposure.add_argument("--reference-mask", metavar="MASK",
                          help="image: the target's pixels are non-zero (default: wherever the scene puts it)")
    exposure.add_argument("--reference-reflectance", type=float, default=0.99,
                          help="the target's reflectance (default 0.99, Spectralon; 0.18 for a grey card)")
    exposure.add_argument("--gain", type=float, help="the camera's gain: photo value per unit linear radiance")
    exposure.add_argument("--gain-err", type=float, default=0.0,
                          help="relative standard error of --gain (default 0: held)")
    exposure.add_argument("--no-gain", action="store_true",
                          help="the photo is calibrated radiance: the gain is 1")
    exposure.add_argument("--fit-gain", action="store_true",
                          help="fit the gain (unresolved from R_d unless the photo pins it)")
    p.add_argument("--no-specular", action="store_true", help="the photo holds subsurface light only")
    p.add_argument("--highlight", choices=("auto", "fit", "mask", "model"), default="auto",
                   help="the specular highlight in the photo: fit its Beckmann roughness, mask its pixels (where it "
                        "may be wrong by 2 %% or more of the light for a roughness within 2x of the scene's), or model it at "
                        "the scene's roughness; auto (default): fit where the highlight is in the photo and the "
                        "lights are point or directional, else mask")
    p.add_argument("--albedo-map", nargs="?", const="auto", default=None, metavar="SIZE",
                   help="fit a colour map (texels per side, or auto: about one per pixel's footprint) and one mean "
                        "free path per channel instead of sigma_a and sigma_s' (the scene's reduced albedo held); "
                        "writes PHOTO.albedo.exr, PHOTO.albedo_err.exr and a .fit.toml that renders the map")
    p.add_argument("--export", action="append", choices=sorted(EXPORTS), metavar="FORMAT",
                   help="also write the fitted material for another renderer, beside the .fit.toml: mitsuba "
                        "(PHOTO.fit_mitsuba.xml), pbrt (PHOTO.fit.pbrt) or blender (PHOTO.fit_blender.py); with "
                        "--albedo-map, mitsuba and blender carry the map as a texture (an EXR beside them); "
                        "repeat for several. Not written when the exposure is unresolved or a map fit did not "
                        "converge (a warning says so)")
    p.add_argument("--unit-mm", type=float, default=1.0,
                   help="millimetres per scene unit of the exported materials (default 1; 1000 for metres)")
    p.add_argument("--rim-mm", type=float, default=0.0,
                   help="leave out pixels within this distance [mm] of an open surface's rim (default 0)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="let the scene name files (OBJ, maps) outside its own folder")
    p.add_argument("--version", action="version", version=version(f"{PROG} fit"))
    p.set_defaults(run=_fit, prog=f"{PROG} fit")


def main(argv=None) -> int:
    """The ``jsss-render`` console script; returns the exit status (2: bad input, one line each)."""
    args = parser().parse_args(argv)
    return exit_status(args.prog, args.run, args)


# ----------------------------------------------------------------------------- rendering
def _outputs(args) -> list[Path]:
    """The PNG path of each scene: -o as a file for one scene, as a directory for several."""
    names = [Path(Path(scene).with_suffix(".png").name) for scene in args.scenes]
    if args.output is None:
        return names
    output = Path(args.output)
    if len(args.scenes) == 1 and output.suffix.lower() == ".png":
        return [output]
    if len(args.scenes) == 1 and not output.is_dir() and output.suffix:
        raise UsageError(f"-o {output}: the output is a PNG (name.png) or a directory; got suffix {output.suffix}.")
    return [output / name for name in names]


def shipped_examples() -> dict[str, Path]:
    """The example scenes that ship with jsss (``jsss.examples``, the repository's examples/),
    by name."""
    try:
        from importlib.resources import files

        folder = Path(str(files("jsss.examples")))
    except ModuleNotFoundError:  # an editable install made before examples shipped as jsss.examples
        import jsss

        folder = Path(jsss.__file__).resolve().parents[1] / "examples"
    return {path.stem: path for path in sorted(folder.glob("*.toml"))}


def _example_paths(scenes) -> list[str]:
    """``example:NAME`` replaced by the shipped scene's path; ``example:list`` prints the names."""
    out = []
    for scene in scenes:
        if not str(scene).startswith("example:"):
            out.append(scene)
            continue
        name, examples = str(scene)[len("example:"):], shipped_examples()
        if name == "list":
            for stem, path in examples.items():
                print(f"example:{stem:<16} {path}")
            continue
        if name not in examples:
            raise UsageError(f"{scene}: no such example; one of {', '.join('example:' + n for n in examples)}")
        out.append(str(examples[name]))
    return out


def _render(args) -> int:
    """Render every scene; a scene that fails is one line on stderr, the others still render
    (exit status 2 if any failed)."""
    args.scenes = _example_paths(args.scenes)
    if not args.scenes:  # example:list alone
        return 0
    outputs = _outputs(args)
    say = Progress(PROG, enabled=False if args.quiet else None)
    start(spectra=True)  # planning fits profiles in float64; float32 frames unless --float64
    failed = 0
    for scene_path, output in zip(args.scenes, outputs):
        try:
            written = _render_one(scene_path, output, args, say)
        except (ValueError, OSError) as error:  # SceneError, ExrError, ...: this scene's, in one line
            print(error_line(PROG, error), file=sys.stderr)
            failed += 1
            continue
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as error:  # noqa: BLE001 -- a bug must not stop the other scenes, nor print a traceback
            if os.environ.get("JSSS_DEBUG"):
                traceback.print_exc()
            print(f"{PROG}: error: {scene_path}: {type(error).__name__} while rendering: {str(error).splitlines()[0] if str(error) else ''} "
                  "(a bug in jsss: please report it with the scene; JSSS_DEBUG=1 prints the traceback)", file=sys.stderr)
            failed += 1
            continue
        print("wrote " + ", ".join(written), flush=True)
    return 2 if failed else 0


def _render_one(scene_path, output: Path, args, say) -> list[str]:
    import jax.numpy as jnp

    from jsss.render import SceneError, load_scene, plan_scene, render
    from jsss.render.budget import MAX_SAMPLES
    from jsss.render.passes import Method
    from jsss.render.shading import tone_map
    from measure.exr import write_exr

    say(f"{scene_path}: loading the scene")
    scene = load_scene(scene_path, allow_outside=args.allow_outside_paths)
    if args.accuracy is not None and not 0 < args.accuracy < 1:
        raise SceneError(f"--accuracy must lie in (0, 1); got {args.accuracy}.")
    if args.samples is not None and not 1 <= args.samples <= MAX_SAMPLES:
        raise SceneError(f"--samples {args.samples}: image-space samples per pixel must lie in [1, {MAX_SAMPLES}] "
                         "(the calibration measures 8, 32 and 128).")
    method = None if args.method == "auto" else Method(args.method)
    if args.accuracy is not None:
        scene = scene.with_accuracy(args.accuracy)  # profile = "auto" chooses for it
    say(f"{scene_path}: planning (fits the material's profile)")
    plan = plan_scene(scene, accuracy=args.accuracy, method=method, samples=args.samples,
                      normal_filter=args.normal_filter)
    if args.plan:
        print(plan.describe(), flush=True)
    say(f"{scene_path}: rendering with {plan.method} (the first frame compiles: 10-20 s)")
    result = render(scene, plan, dtype=jnp.float64 if args.float64 else jnp.float32, time_passes=args.timings)
    check_frame(result.radiance, scene_path)
    image, exposure = tone_map(result.radiance, exposure=scene.exposure)
    write_png(output, image, software=version(PROG))
    written = [str(output)]
    if not args.no_exr:
        exr = output.with_suffix(".exr")
        write_exr(exr, result.radiance, attributes={"jsss_scene": str(scene_path), "jsss_exposure": exposure})
        written.append(str(exr))
    if args.timings:
        print(f"timings (ms) of {scene_path}:")
        for name, seconds in result.timings.items():
            print(f"  {name:<28} {1000 * seconds:9.1f}")
    say(f"{scene_path}: done")
    return written


def check_frame(radiance, scene_path) -> None:
    """Refuse a frame that is not a picture, naming the likely cause: non-finite pixels (an
    overflow or an unphysical material) or no light at all (the camera inside the object, or
    every light behind it). Nothing is written for such a frame."""
    import numpy as np

    from jsss.render import SceneError

    radiance = np.asarray(radiance)
    bad = ~np.isfinite(radiance).all(-1)
    if bad.any():
        raise SceneError(f"{scene_path}: the frame has {int(bad.sum())} of {bad.size} pixels that are NaN or infinite: "
                         "the material or the lights are outside what float32 can carry (try --float64, or smaller "
                         "intensities and coefficients); nothing written.")
    if not np.any(radiance > 0):
        raise SceneError(f"{scene_path}: the frame is black: no lit surface faces the camera (is the camera inside "
                         "the object, or every light behind it or below the surface?); nothing written.")


# ----------------------------------------------------------------------------- fit
def _read_mask(path, shape):
    import numpy as np

    from measure.photo import read_image

    suffix = Path(path).suffix.lower()
    if suffix in (".png", ".jpg", ".jpeg", ".bmp") and not _is_16bit_png(path):
        import matplotlib.image

        pixels = np.asarray(matplotlib.image.imread(path), float)
    else:
        pixels = read_image(path).pixels
    pixels = pixels if pixels.ndim == 2 else pixels[..., :3].max(-1)
    if pixels.shape != shape:
        raise UsageError(f"--mask {path}: {pixels.shape[1]} x {pixels.shape[0]} pixels, but the photo is "
                         f"{shape[1]} x {shape[0]}.")
    return pixels > 0


def _is_16bit_png(path) -> bool:
    with open(path, "rb") as f:
        head = f.read(25)
    return head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) > 24 and head[24] == 16


def _figure(photo, result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from jsss.render.shading import tone_map

    shown, exposure = tone_map(photo)
    fit, _ = tone_map(result.image, exposure=exposure)
    residual = np.where(result.mask, ((result.image - photo) / result.sigma).mean(-1) * np.sqrt(3), np.nan)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), constrained_layout=True)
    axes[0].imshow(shown)
    axes[0].set_title("photo")
    axes[1].imshow(fit)
    axes[1].set_title(f"fit ({result.method}, {result.profile_model})")
    im = axes[2].imshow(residual, cmap="RdBu_r", vmin=-4, vmax=4)
    axes[2].set_title("(fit - photo) / noise, fitted pixels")
    fig.colorbar(im, ax=axes[2], shrink=0.85)
    for ax in axes:
        ax.set_axis_off()
    fig.savefig(path, dpi=110, format="png")  # the path may be a temporary name without a suffix
    plt.close(fig)


def _fit(args) -> int:
    say = Progress(args.prog, enabled=False if args.quiet else None)
    noise = args.noise
    if noise != "estimate":
        try:
            noise = float(noise)
        except ValueError:
            noise = math.nan
        if not (math.isfinite(noise) and noise > 0):
            raise UsageError(f"--noise must be 'estimate' or a relative error > 0 (0.01 for 1 %); got {args.noise}.")
    if not 0 < args.accuracy < 1:
        raise UsageError(f"--accuracy must lie in (0, 1); got {args.accuracy}.")
    if args.model_error is not None and not (math.isfinite(args.model_error) and 0 <= args.model_error < 1):
        raise UsageError(f"--model-error must be a relative error in [0, 1) (0.015 for 1.5 %); got {args.model_error:g}.")
    start(spectra=True)
    from fitting.render import fit_render
    from jsss.render import load_scene
    from jsss.render.passes import Method
    from measure.photo import read_image

    from ._scene_files import export_material, fitted_material, scene_with_material

    if args.saturation is not None and not (math.isfinite(args.saturation) and args.saturation > 0):
        raise UsageError(f"--saturation must be > 0 (the pixel value at which the camera clipped); "
                         f"got {args.saturation:g}")
    if not (math.isfinite(args.unit_mm) and args.unit_mm > 0):
        raise UsageError(f"--unit-mm must be > 0 (millimetres per scene unit: 1 for mm, 1000 for metres); "
                         f"got {args.unit_mm:g}")
    if Path(args.output).exists() and not Path(args.output).is_dir():
        raise UsageError(f"-o {args.output}: is a file; give a folder for the .fit.json, .fit.toml and .fit.png")
    args.scene = (_example_paths([args.scene]) or [args.scene])[0]
    say(f"{args.scene}: loading the scene and the photo")
    scene = load_scene(args.scene, allow_outside=args.allow_outside_paths)
    photo = read_image(args.photo).pixels
    if photo.ndim == 3 and photo.shape[2] >= 3:
        photo = photo[..., :3]
    if not (photo > 0).any():
        raise UsageError(f"{args.photo}: holds no light (no pixel above 0); a fit needs a photo of the lit object")
    mask = _read_mask(args.mask, photo.shape[:2]) if args.mask else None
    method = None if args.method == "auto" else Method(args.method)
    if args.albedo_map is not None:
        from . import _fit_map

        _fit_map.check_flags(args)
        _fit_map.map_size(args.albedo_map)
        gain, gain_err, exposure = _exposure(args, photo, say)
        return _fit_map.fit_map(args, scene, photo, mask, noise, gain, gain_err, exposure, say)
    gain, gain_err, exposure = _exposure(args, photo, say)
    t0 = time.perf_counter()
    model_error = {} if args.model_error is None else {"model_error": args.model_error}
    result = fit_render(scene, photo, noise=noise, loss=args.loss, mask=mask, saturation=args.saturation, method=method,
                        accuracy=args.accuracy, **model_error, profile_model=args.profile, g=args.g, gain=gain, gain_err=gain_err,
                        specular=not args.no_specular, highlight=args.highlight, rim_mm=args.rim_mm,
                        progress=lambda line: say(f"{args.scene}: {line}"))
    seconds = time.perf_counter() - t0
    stem = Path(args.photo).name.rsplit(".", 1)[0]
    summary = result.as_dict() | {"scene": str(args.scene), "photo": str(args.photo), "seconds": round(seconds, 3),
                                  "exposure": exposure}
    material = scene.material
    fitted = fitted_material(result.medium, profile=summary["profile_model"],
                             g=material.g if args.g is None else args.g,
                             roughness=result.roughness if result.highlight == "fit" else material.roughness,
                             specular=material.specular,
                             comment=f"fitted by jsss-render fit ({summary['profile_model']} profile, "
                                     f"{summary['method']}); errors in the .fit.json")
    as_json = json_safe(summary)  # an unconstrained parameter's infinite error is null in JSON (inf in the table)
    written = write_fit_files(args, stem, as_json, scene_with_material(Path(args.scene).read_text(), fitted),
                              lambda tmp: _figure(photo, result, tmp), result.warnings)
    if not args.json:
        print(f"fitted {args.photo} ({result.method}, {result.profile_model} profile, {result.n_pixels} pixels, "
              f"{result.steps} steps, {seconds:.1f} s, chi2/dof {result.chi2_reduced:.2f})")
        rows = [("sigma_a [1/mm]", summary["sigma_a"], summary["sigma_a_err"]),
                ("sigma_s' [1/mm]", summary["sigma_s_prime"], summary["sigma_s_prime_err"]),
                ("R_d", summary["reflectance"], summary["reflectance_err"]),
                ("mean free path [mm]", summary["mean_free_path_mm"], summary["mean_free_path_err_mm"])]
        for name, values, errors in rows:
            print(f"  {name:<20}" + "  ".join(f"{v:.5g} +- {e:.2g}" for v, e in zip(values, errors)))
        print(f"  {'gain':<20}{summary['gain']:.5g} +- {summary['gain_err']:.2g} ({exposure})")
        print(f"  {'highlight':<20}" + {
            "fit": f"roughness fitted: {result.roughness:.4g} +- {result.roughness_err:.2g}",
            "mask": f"masked: {result.highlight_pixels} pixels left out",
            "model": f"modelled at the scene's roughness {result.roughness:g}, held",
            "none": "none in the fit (--no-specular or the scene's specular = 0)"}[result.highlight])
    if args.export and result.gain_unresolved:
        print(f"{args.prog}: warning: no material exported: the exposure is unresolved", file=sys.stderr)
    elif args.export:
        written += [path for _, path in export_material(args.export, Path(args.output) / f"{stem}.fit", result.medium,
                                                        g=float(fitted["g"]), unit_mm=args.unit_mm)]
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr if args.json else sys.stdout)
    if result.gain_unresolved:
        print(f"{args.prog}: error: the exposure is unresolved, so R_d and sigma_a are not measurements: add a white "
              "target of known reflectance (--reference-scene CARD.toml, --reference-reflectance) or give the gain "
              "(--gain G)", file=sys.stderr)
        return 1
    return 0


def _exposure(args, photo, say):
    """``(gain, gain_err, how)`` for fit_render from the exposure flags (one source, or exit 2)."""
    given = [flag for flag, on in (("--reference-scene", args.reference_scene), ("--gain", args.gain is not None),
                                   ("--no-gain", args.no_gain), ("--fit-gain", args.fit_gain)) if on]
    if len(given) > 1:
        raise UsageError(f"{' and '.join(given)}: give one source of the photo's exposure")
    for flag, value in (("--reference-photo", args.reference_photo), ("--reference-mask", args.reference_mask)):
        if value and not args.reference_scene:
            raise UsageError(f"{flag} goes with --reference-scene CARD.toml (the target's geometry and lights)")
    if not given:
        raise UsageError("the photo's exposure is unknown, and a photo's brightness is gain x R_d: give a white target "
                         "of known reflectance (--reference-scene CARD.toml), the camera's gain (--gain G, or --no-gain "
                         "for calibrated radiance), or --fit-gain (R_d and the gain then stay one direction unless the "
                         "photo pins the gain)")
    if not (math.isfinite(args.gain_err) and args.gain_err >= 0):
        raise UsageError(f"--gain-err must be >= 0 (the gain's relative standard error); got {args.gain_err:g}")
    if args.fit_gain:
        return "fit", 0.0, "fitted"
    if args.no_gain:
        return 1.0, 0.0, "given: --no-gain"
    if args.gain is not None:
        if not (math.isfinite(args.gain) and args.gain > 0):
            raise UsageError(f"--gain must be > 0 (photo value per unit linear radiance); got {args.gain:g}")
        return args.gain, args.gain_err, "given: --gain"
    from fitting.render import gain_from_reference
    from jsss.render import load_scene
    from measure.photo import read_image

    say(f"{args.reference_scene}: the exposure from the reference target")
    card = load_scene(args.reference_scene, allow_outside=args.allow_outside_paths)
    reference = read_image(args.reference_photo).pixels[..., :3] if args.reference_photo else photo
    mask = _read_mask(args.reference_mask, reference.shape[:2]) if args.reference_mask else None
    gain, error = gain_from_reference(card, reference, args.reference_reflectance, mask=mask)
    return gain, error, (f"reference: {args.reference_scene}, reflectance {args.reference_reflectance:g}, "
                         f"gain {gain:.5g} +- {100 * error:.2g} %")


if __name__ == "__main__":
    raise SystemExit(main())
