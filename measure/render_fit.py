"""``jsss-render fit``: a material from a photo of an object whose scene (geometry, camera, lights) is known.

Examples
--------
::

    jsss-render fit examples/marble_sphere.toml photo.exr -o fitted/
    jsss-render fit scene.toml photo.exr --json --profile transport --mask mask.png

Writes ``<photo>.fit.json`` (the parameters with standard errors, the artist's reflectance
and mean free path, the covariance, warnings), ``<photo>.fit.toml`` (the scene with the
fitted material, which ``jsss-render`` renders directly) and ``<photo>.fit.png`` (photo, fit
and whitened residual side by side). ``jsss-render`` without ``fit`` renders scenes
(:mod:`jsss.render.cli`); this module owns the console script so that the fit, which needs
:mod:`fitting` and reads photos, lives above the renderer in the dependency order.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

from jsss.render.passes import Method

PROG = "jsss-render fit"

_EPILOG = """\
The photo is linear (EXR, 16-bit TIFF/PNG or camera raw) at the scene camera's resolution;
pixels are proportional to the radiance toward the camera. The scene's material gives eta,
the surface roughness and the starting guess of sigma_a and sigma_s'. Pixels used: the object
as the camera sees it, without silhouette and grazing pixels, without saturated pixels
(--saturation) and where --mask is non-zero. Exit status 2 on bad input (one line).
"""


def _parser():
    from jsss import __version__

    p = argparse.ArgumentParser(prog=PROG, epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
                                description="Fit sigma_a and sigma_s' per channel (and an exposure gain) of a scene's "
                                            "homogeneous material to a linear HDR photo of it, by inverse rendering.")
    p.add_argument("scene", help="TOML scene file: geometry, camera and lights as photographed")
    p.add_argument("photo", help="linear HDR photo (EXR, 16-bit TIFF/PNG, raw) at the camera's resolution")
    p.add_argument("-o", "--output", default=".", help="directory for the .fit.json/.toml/.png (default: here)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    p.add_argument("--mask", default=None, help="image of the camera's size; pixels where it is 0 are not fitted")
    p.add_argument("--saturation", type=float, default=None,
                   help="pixel value at which the camera clipped; pixels at or above it are not fitted")
    p.add_argument("--noise", type=float, default=0.01,
                   help="relative noise of a pixel (default 0.01); the stated errors widen if the fit is worse")
    p.add_argument("--profile", choices=("dipole", "transport"), default=None,
                   help="profile model (default: the scene's; transport is exact to radiative transfer)")
    p.add_argument("--g", type=float, default=None, help="Henyey-Greenstein g of the transport profile")
    p.add_argument("--method", default="auto", choices=("auto", *(m.option for m in Method)),
                   help="render method during the fit (default: the planner's choice for --accuracy)")
    p.add_argument("--accuracy", type=float, default=0.001,
                   help="accuracy target of the fit's renders (default 0.001: a fit needs a stricter render than "
                        "a display does)")
    p.add_argument("--no-gain", action="store_true",
                   help="the photo is calibrated radiance: hold the exposure gain at 1")
    p.add_argument("--no-specular", action="store_true", help="the photo holds subsurface light only")
    p.add_argument("--rim-mm", type=float, default=0.0,
                   help="leave out pixels within this distance [mm] of an open surface's rim (default 0)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


def _read_mask(path, shape):
    import numpy as np

    from .photo import read_image

    suffix = Path(path).suffix.lower()
    if suffix in (".png", ".jpg", ".jpeg", ".bmp") and not _is_16bit_png(path):
        import matplotlib.image

        pixels = np.asarray(matplotlib.image.imread(path), float)
    else:
        pixels = read_image(path).pixels
    pixels = pixels if pixels.ndim == 2 else pixels[..., :3].max(-1)
    if pixels.shape != shape:
        raise ValueError(f"--mask {path}: {pixels.shape[1]} x {pixels.shape[0]} pixels, but the photo is "
                         f"{shape[1]} x {shape[0]}.")
    return pixels > 0


def _is_16bit_png(path) -> bool:
    with open(path, "rb") as f:
        head = f.read(25)
    return head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) > 24 and head[24] == 16


def fitted_scene_text(scene_text: str, result, *, roughness: float, specular: float, g: float) -> str:
    """The scene file's text with its ``[material]`` table (and sub-tables) replaced by the fit's."""
    as_list = lambda x: "[" + ", ".join(f"{float(v):.9g}" for v in x) + "]"
    d = result.as_dict()
    block = ("[material]\n"
             f"# fitted by jsss-render fit ({d['profile_model']} profile, {d['method']}); errors in the .fit.json\n"
             f"sigma_a = {as_list(d['sigma_a'])}\n"
             f"sigma_s_prime = {as_list(d['sigma_s_prime'])}\n"
             f"eta = {as_list(d['eta'])}\n"
             f"roughness = {roughness:.9g}\n"
             f"specular = {specular:.9g}\n"
             f"profile = \"{d['profile_model']}\"\n"
             f"g = {g:.9g}\n")
    out, skipping = [], False
    header = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\"-]+)\s*\]\]?")
    for line in scene_text.splitlines():
        m = header.match(line)
        if m:
            name = m.group(1).strip('"')
            skipping = name == "material" or name.startswith("material.")
            if name == "material":
                out.append(block)
        if not skipping:
            out.append(line)
    if not any(line.startswith("[material]") for line in out):
        out.append(block)
    return "\n".join(out) + "\n"


def _figure(photo, result, sigma_noise, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from jsss.render.shading import tone_map

    shown, exposure = tone_map(photo)
    fit, _ = tone_map(result.image, exposure=exposure)
    level = np.maximum(np.abs(photo).mean(-1), 1e-300)
    residual = np.where(result.mask, (result.image - photo).mean(-1) / (sigma_noise * level), np.nan)
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


def _run(args, say) -> int:
    from fitting.render import fit_render
    from jsss.render import load_scene

    from .cli import _write_atomically, _write_text
    from .photo import read_image

    say(f"{args.scene}: loading the scene and the photo")
    scene = load_scene(args.scene)
    photo = read_image(args.photo).pixels
    if photo.ndim == 3 and photo.shape[2] >= 3:
        photo = photo[..., :3]
    mask = _read_mask(args.mask, photo.shape[:2]) if args.mask else None
    if not (args.noise > 0):
        raise ValueError(f"--noise must be > 0; got {args.noise}.")
    if not 0 < args.accuracy < 1:
        raise ValueError(f"--accuracy must lie in (0, 1); got {args.accuracy}.")
    method = None if args.method == "auto" else Method(args.method)
    t0 = time.perf_counter()
    result = fit_render(scene, photo, noise=args.noise, mask=mask, saturation=args.saturation, method=method,
                        accuracy=args.accuracy, profile_model=args.profile, g=args.g, gain=not args.no_gain,
                        specular=not args.no_specular, rim_mm=args.rim_mm,
                        progress=lambda line: say(f"{args.scene}: {line}"))
    seconds = time.perf_counter() - t0
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    stem = Path(args.photo).name.rsplit(".", 1)[0]
    summary = result.as_dict() | {"scene": str(args.scene), "photo": str(args.photo), "seconds": round(seconds, 3)}
    material = scene.material
    g = material.g if args.g is None else args.g
    files = {out / f"{stem}.fit.json": json.dumps(summary, indent=2) + "\n",
             out / f"{stem}.fit.toml": fitted_scene_text(Path(args.scene).read_text(), result,
                                                         roughness=material.roughness, specular=material.specular,
                                                         g=g)}
    for path, text in files.items():
        _write_text(path, text)
    figure = out / f"{stem}.fit.png"
    _write_atomically(figure, lambda tmp: _figure(photo, result, args.noise, tmp))
    for warning in result.warnings:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"fitted {args.photo} ({result.method}, {result.profile_model} profile, {result.n_pixels} pixels, "
              f"{result.steps} steps, {seconds:.1f} s, chi2/dof {result.chi2_reduced:.2f})")
        rows = [("sigma_a [1/mm]", summary["sigma_a"], summary["sigma_a_err"]),
                ("sigma_s' [1/mm]", summary["sigma_s_prime"], summary["sigma_s_prime_err"]),
                ("R_d", summary["reflectance"], summary["reflectance_err"]),
                ("mean free path [mm]", summary["mean_free_path_mm"], summary["mean_free_path_err_mm"])]
        for name, values, errors in rows:
            print(f"  {name:<20}" + "  ".join(f"{v:.5g} +- {e:.2g}" for v, e in zip(values, errors)))
        print(f"  {'gain':<20}{summary['gain']:.5g} +- {summary['gain_err']:.2g}")
    print("wrote " + ", ".join(str(p) for p in [*files, figure]), file=sys.stderr if args.json else sys.stdout)
    return 0


def fit_main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from .cli import _enable_x64

    _enable_x64()
    from fitting.render import RenderFitError
    from measure.exr import ExrError
    from jsss.render import SceneError

    start = time.perf_counter()

    def say(message):
        if not args.quiet and sys.stderr.isatty():
            print(f"{PROG}: [{time.perf_counter() - start:5.1f} s] {message}", file=sys.stderr, flush=True)

    try:
        return _run(args, say)
    except (RenderFitError, SceneError, ExrError, ValueError, OSError) as error:
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        print(f"{PROG}: error: {message}", file=sys.stderr)
        return 2


def main(argv=None) -> int:
    """The ``jsss-render`` console script: ``fit`` fits a material; anything else renders scenes."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == "fit":
        return fit_main(argv[1:])
    from jsss.render.cli import main as render_main

    return render_main(argv)


if __name__ == "__main__":
    sys.exit(main())
