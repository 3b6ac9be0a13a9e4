"""``jsss``: the Jensen 2001 table with the dipole's total reflectance beside the published one
(``jsss``, ``jsss table``), and what this installation runs on (``jsss info``)."""

from __future__ import annotations

import argparse

from ._console import Parser, exit_status, float64, version

__all__ = ["info_lines", "main", "parser"]

PROG = "jsss"


def _table(args) -> int:
    float64()
    import numpy as np

    from jsss.diffusion.dipole import total_reflectance
    from jsss.materials import jensen2001, jensen2001_table

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
    (the commands that fit turn it on for themselves).
    """
    import platform
    import sys

    import jax

    from jsss import __version__

    from ._console import cache_dir, compilation_cache_dir

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
        f"jsss cache (JSSS_CACHE_DIR): {cache_dir()}",
        f"compilation cache of the commands (JAX_COMPILATION_CACHE_DIR): {jax_cache}",
        f"devices: {devices}",
    ]


def _info(args) -> int:
    print("\n".join(info_lines()))
    return 0


def parser() -> argparse.ArgumentParser:
    """The ``jsss`` parser: ``table`` (the default) and ``info``."""
    p = Parser(
        prog=PROG,
        description="Print the measured materials of Jensen et al. 2001 (Fig. 5b) with the dipole's total diffuse "
                    "reflectance computed beside the published one; 'jsss info' prints the versions, cache "
                    "directories, float64 setting and devices this installation uses.")
    p.add_argument("--version", action="version", version=version(PROG))
    p.set_defaults(run=_table)
    # No positional of its own: a bare `jsss` is `jsss table` by the defaults above.
    commands = p.add_subparsers(dest="command", metavar="{table,info}",
                                help="table (default): the Jensen 2001 table; info: what this installation runs on")
    commands.add_parser("table", help="the Jensen 2001 table (the default)",
                        description="The Jensen 2001 Fig. 5b table with the dipole's total reflectance.").set_defaults(
        run=_table)
    commands.add_parser("info", help="versions, caches, float64 and devices",
                        description="Versions, cache directories, float64 and JAX's devices.").set_defaults(run=_info)
    return p


def main(argv=None) -> int:
    """The ``jsss`` console script; returns the exit status."""
    args = parser().parse_args(argv)
    return exit_status(PROG, args.run, args)


if __name__ == "__main__":
    raise SystemExit(main())
