"""``jsss`` console script: the Jensen 2001 table with the dipole's total reflectance (``jsss``),
and what this installation runs on (``jsss info``)."""

from __future__ import annotations

import argparse


def _table() -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from .diffusion.dipole import total_reflectance
    from .materials import jensen2001, jensen2001_table

    print(f"{'material':<11} {'eta':>4}  {'published R,G,B':>17}  {'dipole R,G,B':>20}  max |diff|")
    for row in jensen2001_table():
        computed = np.asarray(total_reflectance(jensen2001(row.name)))
        diff = np.max(np.abs(computed - np.asarray(row.diffuse_reflectance)))
        published = " ".join(f"{v:.2f}" for v in row.diffuse_reflectance)
        ours = " ".join(f"{v:.4f}" for v in computed)
        print(f"{row.name:<11} {row.eta:>4.1f}  {published:>17}  {ours:>20}  {diff:.4f}")
    return 0


def _version_of(distribution: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return "not installed"


def info_lines() -> list[str]:
    """Versions, cache directories, float64 and JAX's devices, one ``key: value`` per line.

    Reads the configuration without changing it: float64 is reported as this process has it
    (the console scripts that fit turn it on for themselves).
    """
    import platform
    import sys

    import jax

    from . import __version__
    from fitting.programs import compilation_cache_dir, default_cache_dir

    jax_cache = compilation_cache_dir() or "off (JSSS_COMPILATION_CACHE=0)"
    try:
        devices = ", ".join(f"{d.platform}:{d.id} ({d.device_kind})" for d in jax.devices())
    except RuntimeError as error:  # a misconfigured backend still gets a report
        devices = f"none ({error})"
    return [
        f"jsss: {__version__}",
        f"python: {platform.python_version()} ({sys.executable})",
        *(f"{name}: {_version_of(name)}" for name in ("jax", "jaxlib", "numpy", "scipy", "equinox", "optimistix",
                                                       "OpenEXR", "mitsuba")),
        f"float64 (jax_enable_x64): {'on' if jax.config.jax_enable_x64 else 'off'} in this process",
        f"jsss cache (JSSS_CACHE_DIR): {default_cache_dir()}",
        f"compilation cache of the commands (JAX_COMPILATION_CACHE_DIR): {jax_cache}",
        f"devices: {devices}",
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="jsss",
        description="Print the measured materials of Jensen et al. 2001 (Fig. 5b) with the "
        "dipole's total diffuse reflectance computed beside the published one; 'jsss info' prints "
        "the versions, cache directories, float64 setting and devices this installation uses.",
    )
    from . import __version__

    parser.add_argument("command", nargs="?", default="table", choices=("table", "info"),
                        help="table (default): the Jensen 2001 table; info: what this installation runs on")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    args = parser.parse_args(argv)
    if args.command == "info":
        print("\n".join(info_lines()))
        return 0
    return _table()


if __name__ == "__main__":
    raise SystemExit(main())
