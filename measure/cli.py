"""``fit-params``: measured beam-profile images in, sigma_a / sigma_s' out.

    fit-params MEASUREMENT.exr --reference REF.exr --pixel-mm 0.05 --eta 1.3 [--dark DARK.exr]
               [--reference-reflectance 0.99] [--json] [--plot fit.png]
    fit-params T0.exr T1.exr T2.exr --saturation 0.2 --reference REF.exr ...   (exposure brackets)
    fit-params --demo [--json] [--plot fit.png]
    fit-params batch DIR_OR_GLOB --out table.csv [--eta 1.3] [--pixel-mm 0.05] [--manifest M.csv]

Bad input gives a one-line error and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["main"]

PROG = "fit-params"


class UsageError(ValueError):
    """A problem with the command line or the input files, reported in one line."""


@functools.lru_cache(maxsize=None)
def _enable_x64():
    """Console-script setup of JAX: float64 (fits need it) and the persistent compilation cache.
    Once per process (a batch worker calls it for every image)."""
    import jax

    from fitting.programs import enable_compilation_cache

    jax.config.update("jax_enable_x64", True)
    enable_compilation_cache()


@functools.lru_cache(maxsize=None)
def _grid():
    """The fits' Hankel grid, once per process, and from disk after the first start (building
    it is 3 s of Bessel functions; see :func:`fitting.programs.stored_hankel_grid`)."""
    from fitting.programs import stored_hankel_grid

    _enable_x64()  # the grid's dtype, and the cache it is kept in
    return stored_hankel_grid()


# ----------------------------------------------------------------------------- single measurement
def _merge_frames(paths, saturation, dark, white_balance="none"):
    """Read exposure brackets (exposure time from each file's metadata: the EXR attribute
    ``jsss_exposure``, a raw or TIFF file's exposure time x ISO / 100) and merge them."""
    from .exr import ExrImage
    from .photo import read_image
    from .profile import merge_brackets

    frames = [read_image(p, white_balance=white_balance) for p in paths]
    missing = [str(f.path) for f in frames if "jsss_exposure" not in f.header]
    if missing:
        raise UsageError(f"{missing[0]}: bracket without an exposure time (EXR header attribute jsss_exposure, or "
                         "the exposure time of a raw/TIFF file's metadata)")
    if saturation is None:
        levels = {f.header.get("jsss_saturation") for f in frames}
        if None in levels or len(levels) != 1:
            raise UsageError("several measurement frames need --saturation (the clip level of a frame)")
        saturation = levels.pop()  # raw and integer files know their clip level
    dark_pixels = None if dark is None else read_image(dark, frames[0].channels, white_balance=white_balance).pixels
    merged = merge_brackets([f.pixels for f in frames], [f.header["jsss_exposure"] for f in frames],
                            saturation=saturation, dark=dark_pixels, names=[str(f.path) for f in frames])
    return ExrImage(merged, frames[0].channels, {**frames[0].header, "jsss_merged": True}, frames[0].path)


def _load_and_fit(measurement, reference, *, pixel_mm, eta, dark=None, reference_reflectance=0.99, model="dipole",
                  g=0.0, view_angle_deg=0.0, grid=None, saturation=None, white_balance="none"):
    from .checks import MeasurementError
    from .pipeline import fit_measurement
    from .photo import read_image

    paths = measurement if isinstance(measurement, (list, tuple)) else [measurement]
    merged = len(paths) > 1
    # Merged brackets are per unit exposure with the dark frame already subtracted.
    meas = (_merge_frames(paths, saturation, dark, white_balance) if merged
            else read_image(paths[0], white_balance=white_balance))
    ref = read_image(reference, meas.channels, white_balance=white_balance)
    dark_img = read_image(dark, meas.channels, white_balance=white_balance) if dark else None
    for img in [ref] + ([dark_img] if dark_img else []):
        if img.pixels.shape != meas.pixels.shape:
            raise UsageError(f"{img.path}: shape {img.pixels.shape} differs from {meas.path} {meas.pixels.shape}")
    if not merged:
        _check_saturation(meas)
    _check_saturation(ref)
    # Dark frame off (it was taken at the frames' exposure), then each frame per unit exposure
    # where its file records one (raw and TIFF metadata, the EXR attribute jsss_exposure), so
    # that a measurement and a reference exposed differently calibrate correctly.
    offset = 0.0 if dark_img is None else dark_img.pixels
    meas_pixels = meas.pixels if merged else (meas.pixels - offset) / meas.header.get("jsss_exposure", 1.0)
    ref_pixels = (ref.pixels - offset) / ref.header.get("jsss_exposure", 1.0)
    if pixel_mm is None:
        pixel_mm = meas.header.get("jsss_pixel_mm")
        if pixel_mm is None:
            raise UsageError(f"{meas.path}: no pixel size in the header (jsss_pixel_mm); pass --pixel-mm")
    if eta is None or not np.isfinite(eta) or eta <= 0:
        raise UsageError(f"--eta must be > 0 (the relative index of refraction, e.g. 1.3); got {eta}")
    if not (np.isfinite(pixel_mm) and pixel_mm > 0):
        raise UsageError(f"--pixel-mm must be > 0 (the pixel size on the sample in mm); got {pixel_mm:g}")
    if not (0 < reference_reflectance <= 1):  # also refuses nan
        raise UsageError(f"--reference-reflectance must be in (0, 1] (0.99 for Spectralon); got {reference_reflectance:g}")
    if view_angle_deg is not None and not (0 <= view_angle_deg < 90):  # also refuses nan
        raise UsageError(f"--view-angle must lie in [0, 90) degrees (the camera's angle from the normal); "
                         f"got {view_angle_deg:g}")
    if model == "transport":
        from jsss import transport

        try:
            transport.check_supported(eta, g)
        except ValueError as error:
            raise UsageError(f"--model transport: {error} (--model dipole fits any eta, with diffusion's bias)") from None
    try:
        return fit_measurement(meas_pixels, ref_pixels, float(pixel_mm), float(eta),
                               reference_reflectance=reference_reflectance, model=model, g=g,
                               view_angle_deg=view_angle_deg,
                               channels=meas.channels, grid=_grid() if grid is None else grid)
    except MeasurementError as error:
        raise UsageError(f"{meas.path} with reference {ref.path}: {error}") from None


def _check_saturation(image):
    """Clipped highlights: pixels at the file's clip level (raw, TIFF, PNG), or in an EXR
    several pixels sharing the exact maximum of a channel."""
    level = image.header.get("jsss_saturation")
    if level is not None and not image.header.get("jsss_merged"):
        clipped = int(np.count_nonzero(np.any(image.pixels >= level, axis=-1)))
        if clipped:
            raise UsageError(f"{image.path}: {clipped} pixel(s) clipped at the sensor's saturation; use a shorter "
                             "exposure or merge brackets")
        return
    for c, name in enumerate(image.channels):
        channel = image.pixels[..., c]
        peak = channel.max()
        if peak > 0 and np.count_nonzero(channel == peak) > 4:
            raise UsageError(f"{image.path}: channel {name} looks saturated ({np.count_nonzero(channel == peak)} "
                             f"pixels at the maximum {peak:g}); use a shorter exposure or merge brackets")


def _format_table(table) -> str:
    lines = [f"{'channel':<8} {'sigma_a [1/mm]':>22} {'sigma_s_prime [1/mm]':>22} {'total R_d':>10} "
             f"{'mfp [mm]':>9} {'rel. resid.':>11}"]
    for i, ch in enumerate(table["channels"]):
        sa = f"{table['sigma_a'][i]:.5g} +- {table['sigma_a_err'][i]:.2g}"
        ss = f"{table['sigma_s_prime'][i]:.5g} +- {table['sigma_s_prime_err'][i]:.2g}"
        lines.append(f"{ch:<8} {sa:>22} {ss:>22} {table['total_reflectance'][i]:>10.4f} "
                     f"{table['mean_free_path_mm'][i]:>9.4f} {table['rel_residual'][i]:>11.2e}")
    return "\n".join(lines)


def _plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jsss import transport
    from jsss.diffusion import dipole

    prof = result.profile
    fig, ax = plt.subplots(figsize=(6, 4))
    r = np.geomspace(max(prof.r_mm[0], 1e-3), prof.r_mm[-1], 200)
    if result.model == "transport":
        model = np.asarray(transport.profile(result.fit.medium, r, g=result.g)).reshape(r.size, -1)
    else:
        model = np.asarray(dipole.profile(result.fit.medium, r)).reshape(r.size, -1)
    colours = {"R": "tab:red", "G": "tab:green", "B": "tab:blue"}
    for c, name in enumerate(result.channels):
        colour = colours.get(name, "k")
        ax.errorbar(prof.r_mm, prof.mean[:, c], yerr=prof.stderr[:, c], fmt=".", ms=3, color=colour,
                    label=f"{name} measured")
        ax.plot(r, model[:, c], "-", color=colour, lw=1, label=f"{name} {result.model} fit")
    ax.set(xscale="log", yscale="log", xlabel="r [mm]", ylabel="R_d(r) [1/mm^2]", title="fit-params")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _say(args, message):
    """A progress line on stderr for the silent seconds (reading, compiling): terminals only, not with --quiet."""
    if not getattr(args, "quiet", False) and sys.stderr.isatty():
        print(f"{PROG}: {message}", file=sys.stderr, flush=True)


def _single(args) -> int:
    if not args.reference:
        raise UsageError("--reference REF.exr is required (or use --demo)")
    _say(args, f"fitting {args.model} to {len(args.measurement)} frame(s) (the first fit compiles: 10-20 s)")
    fit_args = dict(pixel_mm=args.pixel_mm, eta=args.eta, dark=args.dark,
                    reference_reflectance=args.reference_reflectance, g=args.g, view_angle_deg=_view_angle(args),
                    saturation=args.saturation, white_balance=args.white_balance)
    result = _load_and_fit(args.measurement, args.reference, model=args.model, **fit_args)
    comparison = None
    if args.model == "dipole":
        comparison = _dipole_bias(result, lambda: _load_and_fit(args.measurement, args.reference, model="transport",
                                                                **fit_args))
    _report(result, args, extra=comparison, stem=Path(args.measurement[0]).stem)
    return 0


def _dipole_bias(result, fit_transport):
    """Warn where the dipole's known bias exceeds its stated error: refit with the transport
    model (exact to radiative transfer) and compare, channel by channel. Returns the JSON
    entry (relative differences), or None where the tables do not cover eta or g."""
    from jsss import transport

    try:
        transport.check_supported(np.asarray(result.fit.medium.eta), result.g)
    except ValueError:
        return None
    dipole_table, exact = result.table(), fit_transport().table()
    out = {"sigma_a": [], "sigma_s_prime": []}
    for i, channel in enumerate(dipole_table["channels"]):
        for key in out:
            value, error, reference = dipole_table[key][i], dipole_table[f"{key}_err"][i], exact[key][i]
            out[key].append(value / reference - 1)
            if abs(value - reference) > error:  # the same image: the difference is the models', not noise
                print(f"{PROG}: warning: channel {channel}: the dipole's {key} {value:.4g} is {value / reference - 1:+.1%} "
                      f"from the transport model's {reference:.4g} on the same image, {abs(value - reference) / error:.0f} "
                      "times its stated error: diffusion's bias, not noise (use --model transport)", file=sys.stderr)
    return {"dipole_minus_transport": out}


def _warn_quality(table, stream=sys.stderr):
    """One warning line per channel whose residual is far beyond its noise model."""
    for channel, quality in zip(table["channels"], table["quality"]):
        if quality != "ok":
            print(f"{PROG}: warning: channel {channel}: {quality}", file=stream)


EXPORTS = {"mitsuba": "_mitsuba.xml", "pbrt": ".pbrt", "blender": "_blender.py"}


def _write_exports(result, args, stem) -> list[str]:
    """The fitted material for other renderers (--export) and as a jsss scene (--scene).

    Returns the lines that say what was written (stdout, or stderr with --json)."""
    from . import export

    said = []
    medium, g = result.fit.medium, result.g
    prefix = Path(args.export_to) if args.export_to else Path(stem)
    for kind in dict.fromkeys(args.export or []):
        path = prefix.with_name(prefix.name + EXPORTS[kind])
        if kind == "mitsuba":
            text = export.mitsuba_xml(medium, g=g, unit_mm=args.unit_mm, name=prefix.name)
        elif kind == "pbrt":
            text = export.pbrt_material(medium, g=g, unit_mm=args.unit_mm, name=prefix.name)
        else:
            text = export.blender_python(medium, g=g, unit_mm=args.unit_mm, name=prefix.name)
        _write_text(path, text)
        said.append(f"{kind} material written to {path}")
    if args.scene:
        from jsss.render.scene import medium_scene_toml

        _write_text(args.scene, medium_scene_toml(medium, label=f"fit-params {stem}", profile=result.model, g=g))
        said.append(f"scene written to {args.scene} (render it: jsss-render {args.scene})")
    return said


def _check_export_arguments(args):
    if not (np.isfinite(args.unit_mm) and args.unit_mm > 0):
        raise UsageError(f"--unit-mm must be > 0 (millimetres per scene unit: 1 for mm, 1000 for metres); "
                         f"got {args.unit_mm:g}")
    if args.export_to and not args.export:
        raise UsageError("--export-to PREFIX goes with --export FORMAT")


def _report(result, args, truth=None, extra=None, stem="fitted"):
    table = {**result.table(), **(extra or {})}
    _warn_quality(table)
    for message in result.warnings:
        print(f"{PROG}: warning: {message}", file=sys.stderr)
    if args.plot:
        _plot(result, args.plot)
    for line in _write_exports(result, args, stem):
        print(line, file=sys.stderr if args.json else sys.stdout)
    if args.json:
        if truth is not None:
            table = {**table, "truth": truth}
        print(json.dumps(table, indent=2))
        return
    print(_format_table(table))
    if truth is not None:
        print("\ntruth beside estimate:")
        print(f"{'channel':<8} {'sigma_a true':>13} {'estimate':>10} {'rel.err':>8} "
              f"{'sigma_s_prime true':>19} {'estimate':>10} {'rel.err':>8}")
        for i, ch in enumerate(table["channels"]):
            ta, ts = truth["sigma_a"][i], truth["sigma_s_prime"][i]
            ea, es = table["sigma_a"][i], table["sigma_s_prime"][i]
            print(f"{ch:<8} {ta:>13.5g} {ea:>10.5g} {ea / ta - 1:>8.2%} {ts:>19.5g} {es:>10.5g} {es / ts - 1:>8.2%}")
    if args.plot:
        print(f"\nplot written to {args.plot}")


def _demo(args) -> int:
    from jsss.materials import jensen2001

    from .synth import synthesize, write_measurement

    marble = jensen2001("marble")
    with contextlib.ExitStack() as stack:
        # Without --keep the files live only as long as the fit; say so rather than name a folder that vanishes.
        directory = Path(args.keep) if args.keep else Path(stack.enter_context(
            tempfile.TemporaryDirectory(prefix="jsss-demo-")))
        synthetic = synthesize(marble, pixel_mm=0.05, size=256, beam_sigma_mm=0.05, photons_per_unit=1e5, seed=1,
                               model="transport", grid=_grid())
        paths = write_measurement(directory, synthetic, name="marble")
        if not args.json:
            where = (f"written to {directory} (marble.exr, marble_ref.exr, marble_dark.exr, marble.json)" if args.keep
                     else "(temporary files; --keep DIR keeps them)")
            print(f"demo: synthetic camera image of marble (transport tables, 256 x 256 px, 0.05 mm pixels, "
                  f"Gaussian beam 0.05 mm, shot and read noise) {where}")
        _say(args, f"fitting {args.model} (the first fit compiles: 10-20 s)")
        result = _load_and_fit(paths["measurement"], paths["reference"], pixel_mm=None, eta=1.5,
                               dark=paths.get("dark"), model=args.model, g=args.g, view_angle_deg=_view_angle(args))
    _report(result, args, truth=synthetic.truth, stem="marble")
    return 0


def _write_atomically(out, write):
    """``write(tmp_path)`` to a temp file beside ``out``, then rename: no partial files."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_text(out, text):
    def write(tmp):
        with open(tmp, "w") as handle:
            handle.write(text)

    _write_atomically(out, write)


# ----------------------------------------------------------------------------- entry point
def _fit_arguments(parser):
    """The options of a fit, shared by a single fit and ``batch``."""
    parser.add_argument("--pixel-mm", type=float, help="pixel size on the sample [mm] (default: EXR header)")
    parser.add_argument("--eta", type=float, default=1.3, help="relative index of refraction (default 1.3)")
    parser.add_argument("--reference-reflectance", type=float, default=0.99,
                        help="total reflectance of the reference (default 0.99, Spectralon)")
    parser.add_argument("--model", default="transport", choices=["dipole", "transport"],
                        help="profile model: transport (default; scaled Monte Carlo tables, exact to radiative "
                             "transfer, eta 1.0-1.6) or dipole (diffusion: tens of percent off near the source)")
    parser.add_argument("--g", type=float, default=0.0,
                        help="Henyey-Greenstein g of the material for --model transport (0, 0.5, 0.8 or 0.9; default 0)")
    parser.add_argument("--white-balance", default="none", choices=("none", "camera", "daylight"),
                        help="multipliers applied to raw files (default none: the white reference calibrates each "
                             "channel); the choice is recorded")
    parser.add_argument("--view-angle", type=float, default=0.0, metavar="DEG",
                        help="the camera's angle from the sample's normal in degrees (default 0: straight down); "
                             "pixels record radiance toward it")
    parser.add_argument("--exitance", action="store_true",
                        help="read pixels as exitance (a simulation's tally of light leaving), not a camera's radiance")


def _view_angle(args):
    return None if args.exitance else args.view_angle


def _version() -> str:
    # From the installed metadata, not ``jsss.__version__``: importing jsss (and JAX) for
    # --help or --version took 6 s.
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"{PROG} (jsss) {version('jsss')}"
    except PackageNotFoundError:  # a source tree that was not installed
        return f"{PROG} (jsss) unknown"


def _parser():
    parser = argparse.ArgumentParser(prog=PROG, description=(
        "Recover sigma_a and sigma_s' per channel from a beam-profile HDR image and a white reference "
        "(Jensen et al. 2001). Also: 'fit-params batch ...' for many files."))
    parser.add_argument("measurement", nargs="*", help="measurement image: EXR (linear HDR), a camera raw file "
                        "(.dng, .cr2, .nef, .arw, ...) or a 16-bit linear TIFF/PNG; or several exposure brackets to "
                        "merge (exposure from each raw/TIFF file's metadata, or the EXR attribute jsss_exposure)")
    parser.add_argument("--reference", help="white-reference image, same beam and camera")
    parser.add_argument("--dark", help="dark-frame image subtracted from both")
    parser.add_argument("--saturation", type=float, help="clip level of a bracket (needed with several frames)")
    _fit_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--plot", help="write a PNG of the profile and the fit")
    parser.add_argument("--export", action="append", choices=sorted(EXPORTS), metavar="FORMAT",
                        help="write the fitted material for another renderer: mitsuba (XML scene, homogeneous medium "
                             "in a dielectric), pbrt (pbrt-v4 subsurface material) or blender (a Python script for a "
                             "Cycles random-walk Principled BSDF); repeat for several")
    parser.add_argument("--export-to", metavar="PREFIX",
                        help="path prefix of the exported files (default: the measurement's name, in the current "
                             "directory): PREFIX_mitsuba.xml, PREFIX.pbrt, PREFIX_blender.py")
    parser.add_argument("--unit-mm", type=float, default=1.0,
                        help="millimetres per scene unit of the exported materials (default 1; 1000 for metres)")
    parser.add_argument("--scene", metavar="OUT.toml",
                        help="write a jsss scene with the fitted material (and the fitted profile model) that "
                             "jsss-render renders as it is")
    parser.add_argument("--demo", action="store_true", help="fit a synthetic marble measurement")
    parser.add_argument("--keep", metavar="DIR",
                        help="with --demo: write the demo's EXRs (and the truth as JSON) to DIR and keep them")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress lines (they go to stderr, and only when it is a terminal)")
    parser.add_argument("--version", action="version", version=_version())
    return parser


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if argv and argv[0] == "batch":
            from .batch import batch

            return batch(argv[1:])
        args = _parser().parse_args(argv)
        _enable_x64()
        if args.keep and not args.demo:
            raise UsageError("--keep DIR goes with --demo (it keeps the demo's images)")
        _check_export_arguments(args)
        if args.demo:
            return _demo(args)
        if not args.measurement:
            raise UsageError("give a MEASUREMENT.exr (with --reference), or --demo, or 'batch'")
        return _single(args)
    except (UsageError, ValueError, OSError) as error:
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        print(f"{PROG}: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
