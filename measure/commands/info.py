"""``jsss``: the Jensen 2001 table with the dipole's total reflectance beside the published one
(``jsss``, ``jsss table``), the measured-material library with its provenance (``jsss
materials [NAME]``) and what this installation runs on (``jsss info``)."""

from __future__ import annotations

import argparse

from ._console import Parser, exit_status, float64, version

__all__ = ["info_lines", "main", "material_reflectance", "parser"]

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


# ----------------------------------------------------------------------------- jsss materials
def material_reflectance(name: str, *, g: float | None = None):
    """Total diffuse reflectance R_d per unit entering flux of a library material, per channel,
    and the model each channel's value comes from.

    ``"transport"``: :func:`jsss.transport.total_reflectance` (exact to radiative transfer) with
    the material's sigma_s' and, by default, the tabulated g (0, 0.5, 0.8, 0.9) nearest the
    material's mean g (:attr:`jsss.materials.LibraryEntry.g_mean`): at low albedo R_d at fixed
    sigma_s' still depends on g (espresso: 0.0106 at g = 0, 0.0040 at g = 0.9, red);
    ``"dipole"``: :func:`jsss.diffusion.dipole.total_reflectance`, for a channel that absorbs
    more than the tables cover (sigma_a / sigma_s' > 1000); ``"none"``: a channel without
    scattering (sigma_s' = 0) returns no diffuse light, R_d = 0 exactly.

    Returns
    -------
    rd : (3,) float array
    models : tuple of 3 str, one per channel
    g : float, the tabulated g used
    """
    import numpy as np

    from jsss import Medium, transport
    from jsss.diffusion import dipole
    from jsss.materials import material, material_entry

    medium = material(name)
    info = transport.table_info()
    if g is None:
        gs = np.asarray(info["gs"], float)
        g = float(gs[np.argmin(np.abs(gs - material_entry(name).g_mean))])
    sigma_a = np.asarray(medium.sigma_a, float)
    sigma_s_prime = np.asarray(medium.sigma_s_prime, float)
    eta = np.asarray(medium.eta, float)
    limit = float(info["absorption"][-1])
    scatters = sigma_s_prime > 0
    tabulated = scatters & (sigma_a <= limit * np.where(scatters, sigma_s_prime, 0.0))
    # the channels the tables do not cover get a stand-in they do, and the dipole's value after
    stand_in = Medium(np.where(tabulated, sigma_a, 0.0), np.where(tabulated, sigma_s_prime, 1.0), eta)
    exact = np.asarray(transport.total_reflectance(stand_in, g=g), float)
    diffusion = np.asarray(dipole.total_reflectance(medium), float)
    rd = np.where(tabulated, exact, np.where(scatters, diffusion, 0.0))
    models = tuple("transport" if t else ("dipole" if s else "none") for t, s in zip(tabulated, scatters))
    return rd, models, g


def _triple(values, spec=".3g") -> str:
    return " ".join(f"{v:<9{spec}}" if spec == ".3g" else f"{v:{spec}}" for v in values).rstrip()


def _material_record(entry, rd, models, g_table) -> dict:
    source = entry.source
    return {"name": entry.name, "label": entry.label, "source": source.short,
            "sigma_a": list(entry.sigma_a), "sigma_s_prime": list(entry.sigma_s_prime),
            "sigma_s": None if entry.sigma_s is None else list(entry.sigma_s), "g": list(entry.g),
            "g_mean": entry.g_mean, "eta": entry.eta,
            "diffuse_reflectance_published": None if entry.diffuse_reflectance is None else list(entry.diffuse_reflectance),
            "total_reflectance": [float(v) for v in rd], "total_reflectance_model": list(models),
            "total_reflectance_g": g_table,
            "note": entry.note, "citation": source.citation, "table": source.table, "units": source.units,
            "conversion": source.conversion, "g_source": source.g, "eta_source": source.eta,
            "uncertainty": source.uncertainty, "transcribed_from": source.transcribed_from}


def _materials(args) -> int:
    float64()
    import json

    from jsss.materials import material_entry, material_names

    names = [material_entry(args.name).name] if args.name else list(material_names())  # ValueError: one line, 2
    records = [_material_record(material_entry(name), *material_reflectance(name)) for name in names]
    if args.json:
        print(json.dumps(records if not args.name else records[0], indent=1))
    elif args.name:
        record = records[0]
        width = max(len(key) for key in record)
        for key, value in record.items():
            shown = _triple(value, ".6g") if isinstance(value, list) and value and isinstance(value[0], float) else (
                " ".join(value) if isinstance(value, list) else value)
            print(f"{key:<{width}}  {'-' if value is None or value == '' else shown}")
    else:
        mark = {"transport": " ", "dipole": "*", "none": "-"}
        print(f"{'material':<27} {'source':<15} {'sigma_a [1/mm] R G B':<29} {'sigma_s_prime [1/mm] R G B':<29} "
              f"{'g R G B':<17} {'eta':>4}  R_d R G B (at g)")
        for r in records:
            rd = " ".join(f"{v:.4f}{mark[m]}" for v, m in zip(r["total_reflectance"], r["total_reflectance_model"]))
            print(f"{r['name']:<27} {r['source']:<15} {_triple(r['sigma_a']):<29} {_triple(r['sigma_s_prime']):<29} "
                  f"{_triple(r['g'], '.3f'):<17} {r['eta']:>4.2f}  {rd} ({r['total_reflectance_g']:g})".rstrip())
        print(f"{len(records)} materials. R_d: total diffuse reflectance per unit entering flux, from the transport "
              "tables (exact to transport) with the material's sigma_s' at the tabulated g nearest its mean g "
              "(in brackets); * a channel beyond the tables (sigma_a/sigma_s' > 1000): the dipole's; - a channel "
              "without scattering (sigma_s' = 0): none. 'jsss materials NAME' prints one entry with its provenance.")
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
    """The ``jsss`` parser: ``table`` (the default), ``materials`` and ``info``."""
    p = Parser(
        prog=PROG,
        description="Print the measured materials of Jensen et al. 2001 (Fig. 5b) with the dipole's total diffuse "
                    "reflectance computed beside the published one; 'jsss materials' lists the whole measured-"
                    "material library (Jensen 2001, Narasimhan 2006) with its provenance; 'jsss info' prints the "
                    "versions, cache directories, float64 setting and devices this installation uses.")
    p.add_argument("--version", action="version", version=version(PROG))
    p.set_defaults(run=_table)
    # No positional of its own: a bare `jsss` is `jsss table` by the defaults above.
    commands = p.add_subparsers(dest="command", metavar="{table,materials,info}",
                                help="table (default): the Jensen 2001 table; materials: the measured-material "
                                     "library; info: what this installation runs on")
    commands.add_parser("table", help="the Jensen 2001 table (the default)",
                        description="The Jensen 2001 Fig. 5b table with the dipole's total reflectance.").set_defaults(
        run=_table)
    materials = commands.add_parser(
        "materials", help="the measured materials (Jensen 2001, Narasimhan 2006) with their provenance",
        description="Every measured material of jsss.materials: sigma_a, sigma_s' [1/mm], g, eta and the total "
                    "diffuse reflectance R_d per channel; with NAME, one entry's full provenance (citation, table, "
                    "units, conversion, uncertainty).")
    materials.add_argument("name", nargs="?", metavar="NAME",
                           help="one material (any case; spaces or underscores): print its whole record")
    materials.add_argument("--json", action="store_true", help="print JSON (a list, or one record with NAME)")
    materials.set_defaults(run=_materials)
    commands.add_parser("info", help="versions, caches, float64 and devices",
                        description="Versions, cache directories, float64 and JAX's devices.").set_defaults(run=_info)
    return p


def main(argv=None) -> int:
    """The ``jsss`` console script; returns the exit status."""
    args = parser().parse_args(argv)
    return exit_status(PROG, args.run, args)


if __name__ == "__main__":
    raise SystemExit(main())
