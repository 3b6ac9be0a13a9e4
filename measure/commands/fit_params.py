"""``fit-params``: measured beam-profile images in, sigma_a / sigma_s' out.

    fit-params MEASUREMENT.exr --reference REF.exr --pixel-mm 0.05 --eta 1.3 [--dark DARK.exr]
               [--reference-reflectance 0.99] [--json] [--plot fit.png]
    fit-params T0.exr T1.exr T2.exr --saturation 0.2 --reference REF.exr ...   (exposure brackets)
    fit-params --demo [--json] [--plot fit.png]
    fit-params batch DIR_OR_GLOB --out table.csv [--eta 1.3] [--pixel-mm 0.05] [--manifest M.csv]
    fit-params pixel-size CHECKERBOARD.png --square-mm 2   (measure the pixel size on the sample)

The measurement itself is :mod:`measure.files` (read and check the files, fit them); this
module is the command line around it. Bad input gives a one-line error and exit status 2,
never a traceback. A channel whose fit is poor (chi2/dof above 100: residuals ten times its
noise, :data:`measure.checks.NOT_A_RESULT_CHI2`) is not a result: its place in the table, the JSON and a
batch row is empty, its numbers go under ``estimate``, and the command exits 1 unless
``--accept-poor`` is given.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import glob
import json
import logging
import math
import os
import re
import sys
import tempfile
import time
from pathlib import Path

from ._console import (
    Parser,
    Progress,
    UsageError,
    add_commands,
    exit_status,
    fit_grid,
    json_safe,
    release_compiled_programs,
    start,
    version,
    write_atomically,
    write_text,
)
from ._scene_files import EXPORTS

__all__ = ["main", "parser"]

PROG = "fit-params"


# How measure.files names the arguments in its messages: as this command's options.
OPTION_NAMES = {"eta": "--eta", "pixel_mm": "--pixel-mm", "reference_reflectance": "--reference-reflectance",
                "view_angle_deg": "--view-angle", "model": "--model", "saturation": "--saturation"}


# ----------------------------------------------------------------------------- command line
def _fit_options(parser):
    """The options of a fit, shared by a single fit and ``batch``."""
    parser.add_argument("--pixel-mm", type=float,
                        help="pixel size on the sample [mm] (default: EXR header). No fit can check it: every "
                             "coefficient scales as 1/pixel size. Measure it: fit-params pixel-size --help")
    parser.add_argument("--eta", type=float, help="relative index of refraction (default 1.3)")
    parser.add_argument("--reference-reflectance", type=float,
                        help="total reflectance of the reference (default 0.99, Spectralon)")
    parser.add_argument("--model", default="transport", choices=["dipole", "transport"],
                        help="profile model: transport (default; scaled Monte Carlo tables, exact to radiative "
                             "transfer, eta 1.0-1.6) or dipole (diffusion: tens of percent off near the source)")
    parser.add_argument("--g", type=float, default=0.0,
                        help="Henyey-Greenstein g of the material for --model transport (0, 0.5, 0.8 or 0.9; default 0)")
    parser.add_argument("--white-balance", choices=("none", "camera", "daylight"),
                        help="multipliers applied to raw files (default none: the white reference calibrates each "
                             "channel); the choice is recorded")
    parser.add_argument("--view-angle", type=float, default=0.0, metavar="DEG",
                        help="the camera's angle from the sample's normal in degrees (default 0: straight down); "
                             "pixels record radiance toward it")
    parser.add_argument("--exitance", action="store_true",
                        help="read pixels as exitance (a simulation's tally of light leaving), not a camera's radiance")
    parser.add_argument("--accept-poor", action="store_true",
                        help="exit 0 even where a channel's fit is poor (chi2/dof above 100); its values "
                             "stay out of the result's place either way, in 'estimate'")


def _single_options() -> argparse.ArgumentParser:
    """The options of a single fit (and --demo), as a parent of the command's parsers."""
    options = argparse.ArgumentParser(add_help=False)
    options.add_argument("--reference", help="white-reference image, same beam and camera")
    options.add_argument("--dark", help="dark-frame image subtracted from both")
    options.add_argument("--saturation", type=float, help="clip level of a bracket (needed with several frames)")
    _fit_options(options)
    options.add_argument("--json", action="store_true", help="print JSON instead of a table")
    options.add_argument("--plot", help="write a PNG of the profile and the fit")
    options.add_argument("--export", action="append", choices=sorted(EXPORTS), metavar="FORMAT",
                         help="write the fitted material for another renderer: mitsuba (XML scene, homogeneous "
                              "medium in a dielectric), pbrt (pbrt-v4 subsurface material) or blender (a Python "
                              "script for a Cycles random-walk Principled BSDF); repeat for several")
    options.add_argument("--export-to", metavar="PREFIX",
                         help="path prefix of the exported files (default: the measurement's name, in the current "
                              "directory): PREFIX_mitsuba.xml, PREFIX.pbrt, PREFIX_blender.py")
    options.add_argument("--unit-mm", type=float, default=1.0,
                         help="millimetres per scene unit of the exported materials (default 1; 1000 for metres)")
    options.add_argument("--scene", metavar="OUT.toml",
                         help="write a jsss scene with the fitted material (and the fitted profile model) that "
                              "jsss-render renders as it is")
    options.add_argument("--demo", action="store_true", help="fit a synthetic marble measurement")
    options.add_argument("--keep", metavar="DIR",
                         help="with --demo: write the demo's EXRs (and the truth as JSON) to DIR and keep them")
    options.add_argument("-q", "--quiet", action="store_true",
                         help="no progress lines (they go to stderr, and only when it is a terminal)")
    options.add_argument("--version", action="version", version=version(PROG))
    return options


_DESCRIPTION = ("Recover sigma_a and sigma_s' per channel from a beam-profile HDR image and a white reference "
                "(Jensen et al. 2001). Also: 'fit-params batch ...' for many files.")
_MEASUREMENT_HELP = ("measurement image: EXR (linear HDR), a camera raw file (.dng, .cr2, .nef, .arw, ...) or a 16-bit "
                     "linear TIFF/PNG; or several exposure brackets to merge (exposure from each raw/TIFF file's "
                     "metadata, or the EXR attribute jsss_exposure)")


def parser() -> argparse.ArgumentParser:
    """The ``fit-params`` parser: a single fit (the default command) and the ``batch`` subcommand."""
    options = _single_options()
    single = Parser(prog=PROG, description=_DESCRIPTION, parents=[options])
    single.add_argument("measurement", nargs="+", help=_MEASUREMENT_HELP)
    top = Parser(prog=PROG, description=_DESCRIPTION, parents=[options])
    top.set_defaults(run=_fit, measurement=[])
    commands = add_commands(top, default=single, dest="command", metavar="MEASUREMENT ... | batch",
                            help=f"{_MEASUREMENT_HELP}; or the subcommand:")
    _batch_parser(commands)
    _pixel_size_parser(commands)
    return top


def _pixel_size_parser(commands):
    sizer = commands.add_parser(
        "pixel-size", help="measure the pixel size on the sample from a checkerboard photo (fit-params pixel-size --help)",
        description=("Measure the pixel size on the sample from a photo of a printed checkerboard lying where the "
                     "sample lies, same camera and lens setting (measure.target): a beam-profile fit cannot see "
                     "scale, so a wrong --pixel-mm fits as well as the right one, with every coefficient off by "
                     "the same factor. The board may be turned; it should fill most of the frame."))
    sizer.add_argument("image", help="the checkerboard photo: EXR, camera raw, TIFF, PNG or JPEG (8 bits will do)")
    sizer.add_argument("--square-mm", type=float, required=True, help="the printed squares' edge [mm]")
    sizer.add_argument("--json", action="store_true", help="print JSON instead of a sentence")
    sizer.add_argument("--version", action="version", version=version(f"{PROG} pixel-size"))
    sizer.set_defaults(run=_pixel_size)


def _pixel_size(args) -> int:
    from measure.target import checker_square_px

    if not (math.isfinite(args.square_mm) and args.square_mm > 0):
        raise UsageError(f"--square-mm must be > 0 (the printed squares' edge in mm); got {args.square_mm:g}")
    path = Path(args.image)
    if not path.is_file():
        raise UsageError(f"{path}: no such file")
    pixels = _read_any(path)
    try:
        square_px = checker_square_px(pixels)
    except ValueError as error:
        raise UsageError(f"{path}: {error}") from None
    pixel_mm = args.square_mm / square_px
    if args.json:
        print(json.dumps({"pixel_mm": pixel_mm, "square_px": square_px, "square_mm": args.square_mm,
                          "image": str(path)}, indent=2))
    else:
        print(f"pixel size on the sample: {pixel_mm:.5g} mm (squares of {square_px:.4g} px, {args.square_mm:g} mm); "
              f"pass --pixel-mm {pixel_mm:.5g}")
    return 0


def _read_any(path):
    """Pixels of any image a camera or a phone writes: the measurement formats, and 8-bit files
    (only the pattern's period matters here, not linearity)."""
    from measure.photo import RAW_SUFFIXES, read_image

    if path.suffix.lower() == ".exr" or path.suffix.lower() in RAW_SUFFIXES:
        return read_image(path).pixels
    import imageio.v3 as iio

    try:
        return iio.imread(path)
    except (OSError, ValueError, RuntimeError) as error:  # what imageio's plugins raise on a bad file
        raise UsageError(f"{path}: cannot read the image ({type(error).__name__}: {error})") from None


def _batch_parser(commands):
    batch = commands.add_parser("batch", help="fit many measurements into one table (fit-params batch --help)",
                                description=(
        "Fit many measurements. Naming rule: NAME.exr is a measurement, NAME_ref.exr its reference, NAME_dark.exr "
        "its optional dark frame; or list them in a manifest CSV (columns measurement, reference, and optionally dark, "
        "pixel_mm, eta, reference_reflectance; paths relative to the manifest). A file that fails becomes a row with "
        "status 'failed' and its error."))
    batch.add_argument("target", nargs="?", help="directory or glob of measurement EXRs")
    batch.add_argument("--out", required=True, help="output table (.csv, or .parquet with pyarrow)")
    batch.add_argument("--manifest", help="CSV listing the measurements instead of the naming rule")
    _fit_options(batch)
    batch.add_argument("--workers", type=int, default=1,
                       help="local Dask worker processes fitting in parallel (default 1: in this process); each "
                            "compiles the fit once and reuses it for its images")
    batch.add_argument("--scheduler", metavar="ADDRESS",
                       help="fit on an existing dask.distributed cluster (e.g. tcp://host:8786) instead")
    batch.add_argument("--resume", action="store_true",
                       help="keep the rows of --out that are already fitted (status ok or poor) and fit only the rest")
    batch.add_argument("-q", "--quiet", action="store_true", help="no progress bar (on stderr, also when it is a file)")
    batch.add_argument("--version", action="version", version=version(f"{PROG} batch"))
    batch.set_defaults(run=_batch)


def _view_angle(args):
    return None if args.exitance else args.view_angle


# The options that describe a measured sample, with their defaults. They default to None in the
# parser so that a demo can tell a flag given from a default: the demo makes its own sample.
_SAMPLE_OPTIONS = {"pixel_mm": ("--pixel-mm", None), "eta": ("--eta", 1.3),
                   "reference_reflectance": ("--reference-reflectance", 0.99),
                   "white_balance": ("--white-balance", "none"), "reference": ("--reference", None),
                   "dark": ("--dark", None), "saturation": ("--saturation", None)}


def main(argv=None) -> int:
    """The ``fit-params`` console script; returns the exit status (2: bad input, one line)."""
    args = parser().parse_args(argv)
    args.sample_options_given = [flag for key, (flag, _) in _SAMPLE_OPTIONS.items()
                                 if getattr(args, key, None) is not None]
    for key, (_, default) in _SAMPLE_OPTIONS.items():
        if getattr(args, key, None) is None and hasattr(args, key):
            setattr(args, key, default)
    return exit_status(PROG, args.run, args)


# ----------------------------------------------------------------------------- a single fit
def _fit(args) -> int:
    if args.keep and not args.demo:
        raise UsageError("--keep DIR goes with --demo (it keeps the demo's images)")
    if not (math.isfinite(args.unit_mm) and args.unit_mm > 0):
        raise UsageError(f"--unit-mm must be > 0 (millimetres per scene unit: 1 for mm, 1000 for metres); "
                         f"got {args.unit_mm:g}")
    if args.export_to and not args.export:
        raise UsageError("--export-to PREFIX goes with --export FORMAT")
    for flag, value, example in (("--plot", args.plot, "fit.png"), ("--scene", args.scene, "fitted.toml")):
        if value and Path(value).is_dir():  # checked before the fit, not after it
            raise UsageError(f"{flag} {value}: is a folder; give a file name, e.g. {Path(value) / example}")
    say = Progress(PROG, enabled=False if args.quiet else None)
    if args.demo:
        # A flag the demo would ignore is refused: the demo's marble is made and fitted at its own
        # pixel size and index (it had fitted as if --pixel-mm -1 were fine).
        ignored = args.sample_options_given + (["MEASUREMENT"] if args.measurement else [])
        if ignored:
            raise UsageError(f"{', '.join(ignored)}: --demo makes and fits its own sample (marble, eta 1.5, "
                             f"{DEMO_PIXEL_MM} mm pixels, its own reference); drop {'them' if len(ignored) > 1 else 'it'}, "
                             f"or fit your files without --demo")
        return _demo(args, say)
    if not args.measurement:
        raise UsageError("give a MEASUREMENT.exr (with --reference), or --demo, or 'batch'")
    if not args.reference:
        raise UsageError("--reference REF.exr is required (or use --demo)")
    if args.saturation is not None and not (math.isfinite(args.saturation) and args.saturation > 0):
        raise UsageError(f"--saturation must be > 0 (the pixel value at which the camera clipped); "
                         f"got {args.saturation:g}")
    say(f"reading {len(args.measurement)} frame(s), the reference{' and the dark frame' if args.dark else ''}")
    fit = _read_and_fit(args.measurement, args.reference, dark=args.dark, saturation=args.saturation,
                        white_balance=args.white_balance)

    def fit_model(model):
        return fit(args.eta, pixel_mm=args.pixel_mm, reference_reflectance=args.reference_reflectance, model=model,
                   g=args.g, view_angle_deg=_view_angle(args))

    start()
    say(f"fitting {args.model} (the first fit compiles: 10-20 s)")
    result = fit_model(args.model)
    _refuse_failed(result, f"{args.measurement[0]}: ")
    comparison = _dipole_bias(result, lambda: fit_model("transport")) if args.model == "dipole" else None
    return _report(result, args, extra=comparison, stem=Path(args.measurement[0]).stem)


LIKELY_CAUSES = ("check --pixel-mm (or the EXR's pixel size), --eta, --reference-reflectance and that the "
                 "measurement and the reference share their exposure")


def _refuse_failed(result, where: str = "") -> None:
    """A fit that is not a result ends the command in one line (exit 2; a batch's row: failed)
    naming its reasons (:attr:`measure.pipeline.MeasurementFit.failures`)."""
    reasons = result.failures
    if reasons:
        raise UsageError(f"{where}the fit failed: {'; '.join(reasons)}; {LIKELY_CAUSES}")


def _read_and_fit(measurement, reference, **read_options):
    """Read a measurement (:func:`measure.files.read_measurement`) and return ``fit(eta, **options)``,
    which fits it (:func:`measure.files.fit_images`) on the shared grid; messages name the options."""
    from measure.files import fit_images, read_measurement

    images = read_measurement(measurement, reference, names=OPTION_NAMES, **read_options)

    def fit(eta, **options):
        return fit_images(images, eta, grid=fit_grid(), names=OPTION_NAMES, **options)

    return fit


DEMO_PIXEL_MM = 0.14


def _demo(args, say) -> int:
    from jsss.materials import jensen2001
    from measure.synth import synthesize, write_measurement

    start()
    marble = jensen2001("marble")
    with contextlib.ExitStack() as stack:
        # Without --keep the files live only as long as the fit; say so rather than name a folder that vanishes.
        directory = Path(args.keep) if args.keep else Path(stack.enter_context(
            tempfile.TemporaryDirectory(prefix="jsss-demo-")))
        say("synthesizing the demo's images")
        # 0.14 mm pixels frame 2.1 diffusion lengths of red (the advice of measure.checks), where 0.05 mm framed 0.75
        synthetic = synthesize(marble, pixel_mm=DEMO_PIXEL_MM, size=256, beam_sigma_mm=DEMO_PIXEL_MM,
                               photons_per_unit=1e5, seed=1, model="transport", grid=fit_grid())
        paths = write_measurement(directory, synthetic, name="marble")
        if not args.json:
            where = (f"written to {directory} (marble.exr, marble_ref.exr, marble_dark.exr, marble.json)" if args.keep
                     else "(temporary files; --keep DIR keeps them)")
            print(f"demo: synthetic camera image of marble (transport tables, eta 1.5, 256 x 256 px, {DEMO_PIXEL_MM} mm "
                  f"pixels, Gaussian beam {DEMO_PIXEL_MM} mm, shot and read noise) {where}")
        say(f"fitting {args.model} (the first fit compiles: 10-20 s)")
        fit = _read_and_fit(paths["measurement"], paths["reference"], dark=paths.get("dark"))
        result = fit(1.5, model=args.model, g=args.g, view_angle_deg=_view_angle(args))
    return _report(result, args, truth=synthetic.truth, stem="marble")


def _dipole_bias(result, fit_transport):
    """Warn where the dipole's known bias exceeds its stated error: refit with the transport
    model (exact to radiative transfer) and compare, channel by channel. Returns the JSON
    entry (relative differences), or None where the tables do not cover eta or g."""
    import numpy as np

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


# What a poor channel's result leaves empty (null in JSON, blank in a batch row); the numbers
# move to "estimate" (issue 37: ketchup's red came out -80 % with chi2/dof 6260, printed in the
# table like a measurement).
RESULT_KEYS = ("sigma_a", "sigma_s_prime", "sigma_a_err", "sigma_s_prime_err", "sigma_a_table_err",
               "sigma_s_prime_table_err", "total_reflectance", "mean_free_path_mm")


def _judged_chi2(table: dict) -> list:
    """chi2/dof with the transport tables' own noise counted (``chi2_reduced_tables``), which
    quality and status judge; ``chi2_reduced`` in tables written before it existed."""
    return table.get("chi2_reduced_tables", table["chi2_reduced"])


def with_status(table: dict) -> dict:
    """The table with ``status`` per channel (``poor`` where chi2/dof, the tables' noise counted, is
    not finite or above :data:`measure.checks.NOT_A_RESULT_CHI2`, else ``ok``) and, where a channel is
    poor, its values out of the result's place: ``None`` there, and every channel's numbers kept
    under ``estimate``."""
    from measure.checks import NOT_A_RESULT_CHI2

    status = ["ok" if math.isfinite(chi2) and chi2 <= NOT_A_RESULT_CHI2 else "poor" for chi2 in _judged_chi2(table)]
    out = {**table, "status": status}
    if "poor" in status:
        out["estimate"] = {key: list(table[key]) for key in RESULT_KEYS}
        for key in RESULT_KEYS:
            out[key] = [None if s == "poor" else v for v, s in zip(table[key], status)]
    return out


def _format_table(table) -> str:
    lines = [f"{'channel':<8} {'sigma_a [1/mm]':>22} {'sigma_s_prime [1/mm]':>22} {'total R_d':>10} "
             f"{'mfp [mm]':>9} {'rel. resid.':>11}"]
    for i, ch in enumerate(table["channels"]):
        if table.get("status", ["ok"] * (i + 1))[i] == "poor":
            chi2 = f"poor fit, chi2/dof {_judged_chi2(table)[i]:.3g}: not a measurement"
            lines.append(f"{ch:<8} {chi2:>45} {'-':>10} {'-':>9} {table['rel_residual'][i]:>11.2e}")
            continue
        sa = f"{table['sigma_a'][i]:.5g} +- {table['sigma_a_err'][i]:.2g}"
        ss = f"{table['sigma_s_prime'][i]:.5g} +- {table['sigma_s_prime_err'][i]:.2g}"
        lines.append(f"{ch:<8} {sa:>22} {ss:>22} {table['total_reflectance'][i]:>10.4f} "
                     f"{table['mean_free_path_mm'][i]:>9.4f} {table['rel_residual'][i]:>11.2e}")
    return "\n".join(lines)


def _footer(result, args, table) -> list[str]:
    """What the table's numbers rest on that no residual can show: the field in diffusion lengths,
    the calibration's leverage on sigma_a, and the pixel size (:mod:`measure.checks`)."""
    names = " / ".join(table["channels"])

    def each(key, form):
        return " / ".join(format(value, form) for value in table[key])

    source = "--pixel-mm" if args.pixel_mm else ("the demo" if args.demo else "the measurement's header")
    field = (f"\nfield: {each('field_diffusion_lengths', '.2g')} diffusion lengths ({names}; 2+ lets the profile's "
             "decay measure sigma_a)")
    calibration = ("calibration: a 1 % error in --reference-reflectance or the exposure ratio moves sigma_a by "
                   f"{each('sigma_a_per_calibration', '.2g')} % (not in the stated errors)")
    scale = (f"scale: pixel {result.pixel_mm:.4g} mm from {source}; every coefficient scales as 1/pixel size, which no "
             "fit can check (measure it: fit-params pixel-size)")
    if table.get("model") == "transport":
        share = " / ".join(f"{t / e:.0%}" if e else "-" for t, e in zip(table["sigma_a_table_err"], table["sigma_a_err"]))
        errors = (f"errors: include the transport tables' own Monte Carlo noise ({share} of sigma_a's standard error, {names}); "
                  "it is the same for every image fitted with these tables")
    else:
        errors = "errors: the measurement's noise and the reference's scale only"
    return [field, calibration, scale, errors]


def _plot(result, path):
    """What was fitted, and how well: the calibrated bins (the camera's radiance factor, or exitance)
    with their errors and the fitted model's value in each bin (beam-convolved, averaged over the
    same pixels), and below them the residuals in units of each bin's error. A good fit's residuals
    scatter within +-2; a wrong model's run in arcs of tens."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    prof = result.profile
    fitted = prof.r_mm >= result.r_min_mm
    model, residuals = result.fitted_bins, result.normalized_residuals
    chi2 = np.asarray(result.fit.chi2_reduced, float).reshape(-1)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 5.6), sharex=True, height_ratios=(3, 1.4))
    colours = {"R": "tab:red", "G": "tab:green", "B": "tab:blue"}
    for c, name in enumerate(result.channels):
        colour = colours.get(name, "k")
        top.errorbar(prof.r_mm[fitted], prof.mean[fitted, c], yerr=prof.stderr[fitted, c], fmt=".", ms=3,
                     color=colour, label=f"{name} measured")
        top.plot(prof.r_mm[~fitted], prof.mean[~fitted, c], "x", ms=4, color=colour, alpha=0.5)
        top.plot(prof.r_mm[fitted], model[fitted, c], "-", color=colour, lw=1,
                 label=f"{name} {result.model} fit, chi2/dof {chi2[c]:.3g}")
        bottom.plot(prof.r_mm, residuals[:, c], ".-", ms=3, lw=0.5, color=colour)
    quantity = ("exitance per unit entering flux [1/mm^2]" if result.view_angle_deg is None
                else f"pi (1-F0) L at {result.view_angle_deg:g} deg [1/mm^2]")
    top.set(xscale="log", yscale="log", ylabel=quantity,
            title=f"fit-params: {result.model} model, bins from r = {result.r_min_mm:.3g} mm (x: not fitted)")
    top.legend(fontsize=7)
    for level in (-2, 0, 2):
        bottom.axhline(level, color="0.6", lw=0.6, ls="-" if level == 0 else ":")
    bottom.set(xlabel="r [mm]", ylabel="(data - fit) / error")
    fig.tight_layout()
    kind = Path(path).suffix.lower().lstrip(".") or "png"  # the temporary file's name has no suffix
    write_atomically(path, lambda tmp: fig.savefig(tmp, dpi=120, format=kind))
    plt.close(fig)


def _write_exports(result, args, stem) -> list[str]:
    """The fitted material for other renderers (--export) and as a jsss scene (--scene).

    Returns the lines that say what was written (stdout, or stderr with --json)."""
    from ._scene_files import export_material, fitted_material, sphere_scene

    medium, g = result.fit.medium, result.g
    prefix = Path(args.export_to) if args.export_to else Path(stem)
    said = [f"{kind} written to {path}" for kind, path in
            export_material(args.export or [], prefix, medium, g=g, unit_mm=args.unit_mm)]
    if args.scene:
        write_text(args.scene, sphere_scene(fitted_material(medium, profile=result.model, g=g),
                                            label=f"fit-params {stem}"))
        said.append(f"scene written to {args.scene} (render it: jsss-render {args.scene})")
    return said


def _report(result, args, truth=None, extra=None, stem="fitted") -> int:
    """Print the result (table or JSON), write the plot and the exports; returns the exit status:
    1 where a channel's fit is poor and ``--accept-poor`` was not given, else 0."""
    raw = {**result.table(), **(extra or {})}
    table = with_status(raw)
    poor = [ch for ch, s in zip(table["channels"], table["status"]) if s == "poor"]
    for channel, quality in zip(table["channels"], table["quality"]):
        if quality != "ok":  # a residual far beyond its noise model
            print(f"{PROG}: warning: channel {channel}: {quality}", file=sys.stderr)
    for message in result.warnings:
        print(f"{PROG}: warning: {message}", file=sys.stderr)
    if args.plot:
        _plot(result, args.plot)
    if poor and not args.accept_poor and (args.export or args.scene):
        print(f"{PROG}: warning: no material exported: the fit of channel(s) {', '.join(poor)} is poor "
              "(--accept-poor exports it)", file=sys.stderr)
    else:
        for line in _write_exports(result, args, stem):
            print(line, file=sys.stderr if args.json else sys.stdout)
    if args.json:
        if truth is not None:
            table = {**table, "truth": truth}
        print(json.dumps(json_safe(table), indent=2, allow_nan=False))
    else:
        print(_format_table(table))
        print("\n".join(_footer(result, args, table)))
        if truth is not None:
            print("\ntruth beside estimate:")
            print(f"{'channel':<8} {'sigma_a true':>13} {'estimate':>10} {'rel.err':>8} "
                  f"{'sigma_s_prime true':>19} {'estimate':>10} {'rel.err':>8}")
            for i, ch in enumerate(table["channels"]):
                ta, ts = truth["sigma_a"][i], truth["sigma_s_prime"][i]
                ea, es = raw["sigma_a"][i], raw["sigma_s_prime"][i]
                print(f"{ch:<8} {ta:>13.5g} {ea:>10.5g} {ea / ta - 1:>8.2%} {ts:>19.5g} {es:>10.5g} {es / ts - 1:>8.2%}")
        if args.plot:
            print(f"\nplot written to {args.plot}")
    if poor and not args.accept_poor:
        chi2 = ", ".join(f"{c:.3g}" for c, s in zip(_judged_chi2(raw), table["status"]) if s == "poor")
        print(f"{PROG}: error: the fit of channel(s) {', '.join(poor)} is poor (chi2/dof {chi2}), not a measurement: "
              f"{LIKELY_CAUSES}; the estimate is kept apart ('estimate' in --json); --accept-poor exits 0",
              file=sys.stderr)
        return 1
    return 0


# ----------------------------------------------------------------------------- batch
_ROLE = re.compile(r"_(ref|dark)$|_ref_t\d+$|_t\d+$")


def _find_jobs(target, manifest):
    """(measurement, reference, dark, overrides) tuples from a manifest or the naming rule."""
    if manifest:
        manifest = Path(manifest)
        if not manifest.is_file():
            raise UsageError(f"{manifest}: no such manifest")
        jobs = []
        try:
            with manifest.open(newline="", encoding="utf-8") as handle:
                reader = csv.DictReader(handle)
                if not reader.fieldnames or not {"measurement", "reference"} <= set(reader.fieldnames):
                    raise UsageError(f"{manifest}: needs columns "
                                     "measurement,reference[,dark,pixel_mm,eta,reference_reflectance]")
                for line, row in enumerate(reader, start=2):
                    base = manifest.parent
                    if not row.get("measurement") or not row.get("reference"):
                        raise UsageError(f"{manifest}: line {line}: needs a measurement and a reference")
                    overrides = {}
                    for key in ("pixel_mm", "eta", "reference_reflectance"):
                        if row.get(key):
                            try:
                                overrides[key] = float(row[key])
                            except ValueError:
                                raise UsageError(f"{manifest}: line {line}: {key} {row[key]!r} is not a number") from None
                    jobs.append((base / row["measurement"], base / row["reference"],
                                 (base / row["dark"]) if row.get("dark") else None, overrides))
        except UnicodeDecodeError as error:
            raise UsageError(f"{manifest}: not a CSV manifest: byte {error.start} is not UTF-8") from None
        except csv.Error as error:
            raise UsageError(f"{manifest}: not a readable CSV manifest ({error})") from None
        return jobs
    path = Path(target)
    if not path.is_dir() and not glob.has_magic(str(target)):
        raise UsageError(f"{target}: no such directory" + ("" if not path.exists() else " (a file: give its directory, "
                                                           "a glob or --manifest)"))
    from measure.photo import RAW_SUFFIXES

    suffixes = {".exr", ".tif", ".tiff", ".png", *RAW_SUFFIXES}
    candidates = sorted(path.iterdir()) if path.is_dir() else sorted(Path(p) for p in glob.glob(str(target)))
    candidates = [p for p in candidates if p.suffix.lower() in suffixes and not _ROLE.search(p.stem)]
    if not candidates:
        raise UsageError(f"{target}: no measurement images found (NAME.exr, or a raw, TIFF or PNG file, with "
                         "NAME_ref beside it)")
    jobs = []
    for m in candidates:
        dark = m.with_name(f"{m.stem}_dark{m.suffix}")
        jobs.append((m, m.with_name(f"{m.stem}_ref{m.suffix}"), dark if dark.exists() else None, {}))
    return jobs


_ROW_KEYS = ("sigma_a", "sigma_s_prime", "sigma_a_err", "sigma_s_prime_err", "sigma_a_table_err",
             "sigma_s_prime_table_err", "total_reflectance", "mean_free_path_mm",
             "rel_residual", "chi2_reduced", "chi2_reduced_tables", "converged", "quality", "field_diffusion_lengths")


def _fit_row(job, options) -> dict:
    """One batch row: the fit of one measurement, or its failure (recorded, never dropped).

    A plain function of picklable arguments, so that it runs the same in this process or on
    a Dask worker (where the compiled fit and the grid stay warm between images)."""
    start()
    measurement, reference, dark, overrides = job
    row = {"file": str(measurement), "status": "ok", "error": "", "warnings": ""}
    try:
        fit = _read_and_fit(measurement, reference, dark=dark, white_balance=options["white_balance"])
        result = fit(overrides.get("eta", options["eta"]), pixel_mm=overrides.get("pixel_mm", options["pixel_mm"]),
                     reference_reflectance=overrides.get("reference_reflectance", options["reference_reflectance"]),
                     model=options["model"], g=options["g"], view_angle_deg=options["view_angle_deg"])
        _refuse_failed(result)
        table = with_status(result.table())
        for key in _ROW_KEYS:
            for ch, value in zip(table["channels"], table[key]):
                row[f"{key}_{ch}"] = value
        if "estimate" in table:  # a poor channel: blank in the result's place, its numbers beside it
            row["status"] = "poor"
            for key, values in table["estimate"].items():
                for ch, value, status in zip(table["channels"], values, table["status"]):
                    if status == "poor":
                        row[f"{key}_estimate_{ch}"] = value
        row["warnings"] = "; ".join(result.warnings)
    except Exception as error:  # recorded in the table, never dropped
        row.update(status="failed", error=f"{type(error).__name__}: {error}")
    # Images of many sizes compile many programs, each holding memory maps the process may run out of
    release_compiled_programs()
    return row


# Worker processes keep BLAS/OpenMP to one thread each; XLA keeps its own thread pool. On this
# 2-core machine one process already keeps both cores busy (XLA threads the fit's dense
# transforms): forcing one XLA thread per worker made a fit 2.3x slower, and 2 workers of the
# default threading were 0.78-0.84x one process (benchmarks/batch.py). Workers pay off with
# more cores than one fit can use, and on a cluster.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _options(args) -> dict:
    """The fit settings of a batch, as ``_fit_row`` takes them."""
    return dict(pixel_mm=args.pixel_mm, eta=args.eta, reference_reflectance=args.reference_reflectance,
                model=args.model, g=args.g, view_angle_deg=_view_angle(args), white_balance=args.white_balance)


def _settings(job, options) -> str:
    """The settings one row is fitted with (the batch's, with the manifest's overrides), as the
    table's ``settings`` column records them: ``--resume`` keeps a row only where they match."""
    effective = {**options, **job[3]}
    return " ".join(f"{key}={effective[key]!r}" for key in sorted(effective))


def _fitted(jobs, args):
    """Fit every job: in this process (one worker), on local Dask worker processes
    (``--workers N``) or on the cluster at ``--scheduler``. Yields ``(index, row)`` as each
    job finishes (in job order in this process, as they come on workers)."""
    options = _options(args)
    if not jobs:
        return
    # The bar is the batch's record of how far it got: shown in logs too (not only on a terminal), unless -q.
    progress = Progress(f"{PROG} batch", enabled=not args.quiet)
    if args.workers == 1 and not args.scheduler:
        with progress.bar(len(jobs), desc=f"{PROG} batch") as bar:
            for i, job in enumerate(jobs):
                bar.set_postfix_str(job[0].name)
                row = _fit_row(job, options)
                bar.update()
                yield i, row
        return
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsageError("--workers/--scheduler need dask.distributed: pip install 'dask[distributed]'") from None
    with contextlib.ExitStack() as stack:
        if args.scheduler:
            try:
                client = stack.enter_context(Client(args.scheduler, timeout="10s"))
            except OSError as error:
                raise UsageError(f"--scheduler {args.scheduler}: cannot connect ({error})") from None
        else:
            cluster = stack.enter_context(LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None, env=_WORKER_ENV,
                                                       silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
        futures = {client.submit(_fit_row, job, options, pure=False): i for i, job in enumerate(jobs)}
        workers = len(client.scheduler_info()["workers"])
        with progress.bar(len(jobs), desc=f"{PROG} batch, {workers} workers") as bar:
            for future in as_completed(futures):
                i = futures[future]
                try:
                    row = future.result()
                except Exception as error:  # a worker that died: the row still says so
                    row = {"file": str(jobs[i][0]), "status": "failed", "error": f"{type(error).__name__}: {error}"}
                bar.set_postfix_str(jobs[i][0].name, refresh=False)
                bar.update()
                yield i, row


def _read_table(out: Path) -> list[dict]:
    """The rows of a batch table (CSV, or Parquet with pyarrow); one line naming the file otherwise."""
    if out.suffix == ".parquet":
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise UsageError(f"{out}: resuming a .parquet table needs pyarrow") from None
        try:
            return pq.read_table(out).to_pylist()
        except Exception as error:  # noqa: BLE001 -- pyarrow's errors are many; the file is the user's
            raise UsageError(f"{out}: cannot resume: not a readable Parquet table ({error})") from None
    try:
        with out.open(newline="") as handle:
            rows = list(csv.DictReader(handle))
    except (UnicodeDecodeError, csv.Error) as error:
        raise UsageError(f"{out}: cannot resume: not a readable CSV table ({error})") from None
    return rows


def _resumed(jobs, settings, out):
    """Rows already fitted (status ok or poor) with the same settings, by position, and the positions
    still to fit (``--resume``). Rows come from the table ``out`` and then its journal (rows
    that finished after the table was last written: a batch killed outright). A row fitted
    with other settings (another ``--eta``, say) is fitted again."""
    out = Path(out)
    old = _read_table(out) if out.is_file() else []
    if old and "file" not in old[0]:
        raise UsageError(f"{out}: cannot resume: the table has no 'file' column (not a fit-params batch table?); "
                         "resume only a table this command wrote, or drop --resume to overwrite it")
    old += _Journal(out).rows()
    done = {}
    for row in old:
        if row.get("status") in ("ok", "poor") and "file" in row:  # a poor fit is done: it would come out the same
            done[(row["file"], row.get("settings"))] = row
    kept, todo, other = {}, [], 0
    for j, (job, setting) in enumerate(zip(jobs, settings)):
        row = done.get((str(job[0]), setting))
        if row is not None:
            kept[j] = row
        else:
            todo.append(j)
            other += any(file == str(job[0]) for file, _ in done)
    return kept, todo, other


class _Journal:
    """Rows as they finish, one JSON line each, flushed to disk before the next fit starts:
    ``OUT.journal`` beside the table. A batch killed outright (no ``finally`` runs) loses no
    finished row; the table, written whole at the end, replaces the journal."""

    def __init__(self, out: Path):
        self.path = Path(str(out) + ".journal")
        self.handle = None

    def rows(self) -> list[dict]:
        if not self.path.is_file():
            return []
        rows = []
        for line in self.path.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:  # the line being written when the batch was killed
                continue
        return rows

    def append(self, row: dict) -> None:
        if self.handle is None:
            self.handle = self.path.open("a")
        self.handle.write(json.dumps(json_safe(row), allow_nan=False) + "\n")
        self.handle.flush()
        os.fsync(self.handle.fileno())

    def close(self, *, remove: bool) -> None:
        if self.handle is not None:
            self.handle.close()
            self.handle = None
        if remove:
            self.path.unlink(missing_ok=True)


@contextlib.contextmanager
def _locked(out: Path):
    """Hold ``OUT.lock`` for the batch: a second batch writing the same table is refused at once
    (two had both reported success, and one run's rows were gone)."""
    import fcntl

    lock = Path(str(out) + ".lock")
    handle = lock.open("a")
    try:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        raise UsageError(f"--out {out}: another fit-params batch is writing this table (it holds {lock}); "
                         "wait for it, or write to another --out") from None
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)
        handle.close()


def _check_out(out) -> Path:
    """``--out`` before any fit: a .csv or .parquet file in an existing, writable folder."""
    out = Path(out)
    if out.is_dir():
        raise UsageError(f"--out {out}: is a directory; give the table's file name (e.g. {out / 'table.csv'})")
    if out.suffix not in (".csv", ".parquet"):
        raise UsageError(f"--out {out}: the table is .csv (or .parquet with pyarrow); got {out.suffix or 'no suffix'}")
    if not out.parent.is_dir():
        raise UsageError(f"--out {out}: no such folder {out.parent}")
    if not os.access(out.parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise UsageError(f"--out {out}: not writable")
    return out


def _write_table(rows, out):
    """Write CSV (or Parquet) atomically (temp file beside ``out``, then rename): no partial tables."""
    out = Path(out)
    # Columns in the order the rows hold them (the image's channel order, e.g. R, G, B), not sorted.
    columns = list(dict.fromkeys(["file", "status", "error"] + [k for r in rows for k in r]))

    def write(tmp):
        if out.suffix == ".parquet":
            try:
                import pyarrow as pa
                import pyarrow.parquet as pq
            except ImportError:
                raise UsageError(f"{out}: writing .parquet needs pyarrow; install it or use .csv") from None
            pq.write_table(pa.Table.from_pylist([{c: r.get(c) for c in columns} for r in rows]), tmp)
        else:
            with open(tmp, "w", newline="") as handle:
                writer = csv.DictWriter(handle, fieldnames=columns)
                writer.writeheader()
                writer.writerows(rows)

    write_atomically(out, write)


def _run_batch(jobs, settings, out: Path, args) -> list[dict]:
    """Fit the jobs not kept from ``--resume``; every finished row goes to the journal at once
    and the table (atomically) at most once a second and at the end."""
    if args.resume:
        kept, todo, other = _resumed(jobs, settings, out)
    else:
        _Journal(out).close(remove=True)  # a journal of an earlier, killed run is not this run's
        kept, todo, other = {}, list(range(len(jobs))), 0
    if kept or other:
        print(f"resuming: {len(kept)} row(s) of {out} already fitted, {len(todo)} to fit"
              + (f" ({other} fitted with other settings: fitted again)" if other else ""), file=sys.stderr)
    rows = [kept.get(j) for j in range(len(jobs))]  # in job order; None: not fitted yet
    journal = _Journal(out)
    written, unwritten = time.monotonic(), False
    try:
        # Where each job still to fit sits in the table: by position, not by file, since a manifest
        # may list one measurement twice (at two etas, say) and each is a row of its own.
        for i, row in _fitted([jobs[j] for j in todo], args):
            row = {**row, "settings": settings[todo[i]]}
            journal.append(row)
            rows[todo[i]], unwritten = row, True
            if time.monotonic() - written >= 1.0:
                _write_table([r for r in rows if r is not None], out)
                written, unwritten = time.monotonic(), False
    finally:
        if unwritten or not todo:
            _write_table([r for r in rows if r is not None], out)
        journal.close(remove=True)  # the table holds every finished row (a failed write raised above)
    return rows


def _batch(args) -> int:
    """``fit-params batch``; returns the exit status (1 if any row failed, or if any is poor
    without ``--accept-poor``).

    The table is written (atomically) as rows finish, at most once a second, and whatever
    finished is written when the batch stops early (an interrupt, a lost scheduler), so
    ``--resume`` carries on from there."""
    if not args.target and not args.manifest:
        raise UsageError("batch needs a directory/glob or --manifest")
    if args.workers < 1:
        raise UsageError(f"--workers must be at least 1; got {args.workers}")
    out = _check_out(args.out)
    options = _options(args)
    from measure.files import check_options

    check_options(**{key: options[key] for key in ("eta", "pixel_mm", "reference_reflectance", "view_angle_deg",
                                                    "model", "g")}, names=OPTION_NAMES)  # before any fit
    jobs = _find_jobs(args.target, args.manifest)
    settings = [_settings(job, options) for job in jobs]
    with _locked(out):
        rows = _run_batch(jobs, settings, out, args)
    failed = [r for r in rows if r["status"] not in ("ok", "poor")]
    poor = [r for r in rows if r["status"] == "poor"]
    print(f"{len(rows) - len(failed) - len(poor)} fitted, {len(poor)} poor, {len(failed)} failed; "
          f"table written to {args.out}")
    for r in failed:
        print(f"  failed: {r['file']}: {r['error']}", file=sys.stderr)
    for r in poor:
        channels = [key.rsplit("_", 1)[1] for key, value in r.items()
                    if key.startswith("sigma_a_estimate_") and value not in ("", None)]
        print(f"  poor: {r['file']}: channel(s) {', '.join(channels)}: chi2/dof above 100; the estimate is in the "
              "*_estimate_* columns, not a measurement", file=sys.stderr)
    return 1 if failed or (poor and not args.accept_poor) else 0


if __name__ == "__main__":
    raise SystemExit(main())
