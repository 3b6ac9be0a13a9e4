"""``jsss`` console script: the Jensen 2001 table with the dipole's total reflectance."""

from __future__ import annotations

import argparse


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="jsss",
        description="Print the measured materials of Jensen et al. 2001 (Fig. 5b) with the "
        "dipole's total diffuse reflectance computed beside the published one.",
    )
    from . import __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from .dipole import total_reflectance
    from .materials import jensen2001, jensen2001_table

    print(f"{'material':<11} {'eta':>4}  {'published R,G,B':>17}  {'dipole R,G,B':>20}  max |diff|")
    for row in jensen2001_table():
        computed = np.asarray(total_reflectance(jensen2001(row.name)))
        diff = np.max(np.abs(computed - np.asarray(row.diffuse_reflectance)))
        published = " ".join(f"{v:.2f}" for v in row.diffuse_reflectance)
        ours = " ".join(f"{v:.4f}" for v in computed)
        print(f"{row.name:<11} {row.eta:>4.1f}  {published:>17}  {ours:>20}  {diff:.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
