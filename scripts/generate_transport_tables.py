"""Regenerate jsss/data/transport_tables.npz: scaled Monte Carlo tables for jsss.transport.

One absorption-free walk per (eta, g) in transport lengths (sigma_s' = 1, sigma_a = 0),
capped at --max-path transport lengths (the tail beyond is modelled, see
jsss.transport.tables). The walk is jsss.transport.photon_walk, the engine of jsss.transport.montecarlo: its
numbers are counter-based, so a seed reproduces the tables bit for bit on one platform.

Run from the repository root (float64; about 20 minutes on 2 cores for 500 000 photons):
``python scripts/generate_transport_tables.py [--photons 500000] [--seeds 0,1] [--etas 1.0,1.1,...]``
Several seeds are independent runs whose tables are averaged (each rounded to the shipped
float32 first, so averaging files of single seeds gives the same bits). Several processes may
each write a part (``--out part.npz --etas 1.0,1.1 --seeds 1``); ``--merge`` joins parts of
other etas, and ``--average`` parts of the same etas from other seeds (weighted by their
photons). The shipped tables: ``--photons 500000 --seeds 0,1`` (two independent runs of
500 000 photons), then ``--average`` of that file with ``--seeds 2`` and ``--seeds 3``:
2 x 10^6 photons per (eta, g).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from jsss import Medium  # noqa: E402
from jsss.transport.montecarlo import _params  # noqa: E402
from jsss.transport.photon_walk import run_walk  # noqa: E402
from jsss.transport.tables import TableGrid, tabulate  # noqa: E402

ETAS = (1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6)
GS = (0.0, 0.5, 0.8, 0.9)
MAX_PATH = 1000.0  # transport lengths
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "jsss" / "data" / "transport_tables.npz"


def build(etas, gs, *, photons, seed, max_path=MAX_PATH, lanes=4096, progress=True):
    grid = TableGrid()
    shape = (len(etas), len(gs))
    exitance = np.zeros(shape + (grid.rho_edges.size - 1, grid.absorption.size, grid.mu_edges.size - 1))
    total, error_total = np.zeros(shape + (grid.absorption.size,)), np.zeros(shape + (grid.absorption.size,))
    lost, tail_mass = np.zeros(shape), np.zeros(shape)
    for i, eta in enumerate(etas):
        for j, g in enumerate(gs):
            start = time.perf_counter()
            # sigma_s = 1/(1-g) per transport length: every length below is in units of 1/sigma_s'.
            params = _params([Medium(0.0, 1.0, eta)], [np.inf], g=g, eta_above=1 / eta, eta_below=1 / eta,
                             relative=True)
            table_seed = seed * 1000 + int(round(eta * 100)) * 10 + j
            records = run_walk(params, n_photons=photons, lanes=lanes, max_steps=2**31 - 1, max_path=max_path,
                               seed=table_seed, progress=progress, label=f"eta {eta} g {g}")
            out = tabulate(records.radius, records.path, records.exit_cos, records.side == 1, records.side == 0,
                           grid=grid, max_path=max_path)
            exitance[i, j], total[i, j], error_total[i, j] = out["exitance"], out["total"], out["error_total"]
            lost[i, j], tail_mass[i, j] = out["lost"], out["tail_mass"]
            print(f"eta {eta} g {g}: R(a'=0) = {out['total'][0]:.5f}, lost {out['lost']:.4f} "
                  f"(tail model {out['tail_mass']:.4f}), {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return dict(etas=np.asarray(etas, float), gs=np.asarray(gs, float), rho_edges=grid.rho_edges,
                mu_edges=grid.mu_edges, absorption=grid.absorption, exitance=exitance.astype(np.float32),
                total=total, error_total=error_total, lost=lost, tail_mass=tail_mass,
                photons=np.int64(photons), seed=np.int64(seed), max_path=np.float64(max_path))


def average(tables):
    """Tables of the same grids from independent runs, as one table of all their photons.

    Each run weighs by its photons (an average of two seeds counts twice beside a single
    seed of the same photons each); for equal runs this is the plain mean."""
    if len(tables) == 1:
        return tables[0]
    out = dict(tables[0])
    photons = [int(t["photons"]) for t in tables]
    weights = [p / min(photons) for p in photons]
    k = sum(weights)
    out["exitance"] = (sum(w * t["exitance"].astype(np.float64) for w, t in zip(weights, tables)) / k).astype(np.float32)
    for key in ("total", "lost", "tail_mass"):
        out[key] = sum(w * t[key] for w, t in zip(weights, tables)) / k
    out["error_total"] = np.sqrt(sum((w * t["error_total"]) ** 2 for w, t in zip(weights, tables))) / k
    out["photons"] = np.int64(sum(int(t["photons"]) for t in tables))
    out["seed"] = np.array([int(s) for t in tables for s in np.atleast_1d(t["seed"])], np.int64)
    return out


def merge(paths):
    parts = [dict(np.load(p)) for p in paths]
    parts.sort(key=lambda p: p["etas"][0])
    out = dict(parts[0])
    for key in ("etas", "exitance", "total", "error_total", "lost", "tail_mass"):
        out[key] = np.concatenate([p[key] for p in parts])
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--photons", type=int, default=100_000)
    parser.add_argument("--seeds", default="0", help="comma-separated seeds: independent runs, averaged")
    parser.add_argument("--etas", default=",".join(str(e) for e in ETAS))
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--merge", nargs="+", type=Path, help="join parts that hold other etas")
    parser.add_argument("--average", nargs="+", type=Path, help="average parts of the same etas from other seeds")
    args = parser.parse_args()
    if args.merge:
        tables = merge(args.merge)
    elif args.average:
        tables = average([dict(np.load(p)) for p in args.average])
    else:
        etas = [float(e) for e in args.etas.split(",")]
        tables = average([build(etas, GS, photons=args.photons, seed=int(seed)) for seed in args.seeds.split(",")])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **tables)
    tmp.replace(args.out)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.1f} MB)", file=sys.stderr)


if __name__ == "__main__":
    main()
