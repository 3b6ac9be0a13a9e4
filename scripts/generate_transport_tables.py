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
2 x 10^6 photons per (eta, g); then ``--early 20000000 --tables FULL.npz`` (about 45 minutes
on 2 cores): 2 x 10^7 more photons per (eta, g) for the paths up to 4 transport lengths, which
set the light of a low albedo, at g 0.5-0.9 with early turns back toward the surface (see
``add_early``). ``--walked EARLIER.npz`` blends an earlier
run's early walks again (minutes). Last, ``--views 1000000 --tables FULL.npz`` (about 20
minutes in two processes of --etas 1.0,1.1,1.2,1.3 and 1.4,1.5,1.6, then ``--merge``): the early
part's radiance toward exact view directions (see ``add_views``). The shipped file was made
from the one before (10^7 early photons, no turns) by ``--rewalk-gs 0.8,0.9``, ``--rewalk-gs
0.5``, ``--more-early 10000000`` and ``--reblend`` (about 45 minutes in all, see
``rewalk_early``): the same walks, seeds and blend as ``--early 20000000`` makes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jsss import Medium  # noqa: E402
from jsss.transport.montecarlo import _params  # noqa: E402
from jsss.transport.photon_walk import run_walk  # noqa: E402
from jsss.transport.tables import TableGrid, tabulate, tail_total_closed_form  # noqa: E402
from jsss.transport.view_walk import VIEW_DEGREES, view_tables  # noqa: E402

ETAS = (1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6)
GS = (0.0, 0.5, 0.8, 0.9)
MAX_PATH = 1000.0  # transport lengths
EARLY_MAX_PATH = 4.0  # transport lengths: e^{-4a'} leaves the early part all of the light at a' >= 3
EARLY_RUN = 500_000  # photons per early walk (one seed each)
# The early walks' first flight: half at the medium's own rate, the rest 10, 100 and 1000 times
# faster, so that the short paths of a strongly absorbing medium (a' up to 10^3) are well sampled.
FIRST_FLIGHT_RATES = (1.0, 1.0, 1.0, 10.0, 100.0, 1000.0)
# Where the phase function is peaked forward, a low albedo's light is the rare photon that turns
# back within its first collisions: the early walks of these g draw the scatterings among a
# photon's first EARLY_TURNS events from HG mixed with the uniform sphere (photon_walk._early_turn).
# With 10^6 photons the total's error at a' 4 / 10 / 40 / 160 went from 1.07 / 1.64 / 2.45 / 2.90 %
# to 0.54 / 0.56 / 0.72 / 0.84 % (eta 1.5, g 0.9; at a' <= 1 it stayed, 0.49 %), and from 0.62 /
# 0.78 / 0.93 / 1.00 % to 0.45 / 0.56 / 0.65 / 0.69 % (eta 1.4, g 0.5). At g 0 HG is the sphere.
EARLY_TURN_FRACTION = 0.35
EARLY_TURNS = 3
EARLY_TURN_GS = (0.5, 0.8, 0.9)
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "jsss" / "data" / "transport_tables.npz"


def _table_seed(seed, eta, j):
    return seed * 1000 + int(round(eta * 100)) * 10 + j


def _early_seed(run, eta, j):
    """Seeds of the early walks: far from the full walks' (``_table_seed`` of seeds 0-3 is below
    5000) and from the tests' and benchmarks' truths (below 10^6), so no stream is shared."""
    return 7_000_000 + run * 10_000 + int(round(eta * 100)) * 10 + j


def _view_seed(eta, j):
    """Seeds of the view walks (NumPy's generator, not the walk engine's counters): apart from all above."""
    return 9_000_000 + round(float(eta) * 100) * 10 + j


def _walk(eta, g, *, photons, seed, max_path, lanes=4096, progress=False, label="", first_flight_rates=None,
          early_turn=None):
    # sigma_s = 1/(1-g) per transport length: every length below is in units of 1/sigma_s'.
    params = _params([Medium(0.0, 1.0, eta)], [np.inf], g=g, eta_above=1 / eta, eta_below=1 / eta, relative=True)
    if first_flight_rates is not None:  # the start cosine (1: along the normal), then the rates
        params = params + (jnp.asarray(1.0, params[0].dtype), jnp.asarray(first_flight_rates, params[0].dtype))
    if early_turn is not None:  # (uniform fraction, events): after the first flight's rates
        params = params + (jnp.asarray(early_turn[0], params[0].dtype), jnp.asarray(early_turn[1], jnp.int32))
    return run_walk(params, n_photons=photons, lanes=lanes, max_steps=2**31 - 1, max_path=max_path, seed=seed,
                    progress=progress, label=label)


def _early_tables(eta, g, seeds, photons_each, *, max_path, grid, first_flight_rates=None, early_turn=None):
    """The mean of short walks' tables (paths up to ``max_path`` only, no tail), one per seed:
    cells, their second moments (``tabulate``'s ``second``), totals and the totals' errors."""
    parts = []
    for seed in seeds:
        records = _walk(eta, g, photons=photons_each, seed=seed, max_path=max_path,
                        first_flight_rates=first_flight_rates, early_turn=early_turn)
        parts.append(tabulate(records.radius, records.path, records.exit_cos, records.side == 1, records.side == 0,
                              grid=grid, max_path=max_path, model_tail=False, weight=records.weight))
    cells = np.mean([p["exitance"] for p in parts], axis=0)
    second = np.mean([p["second"] for p in parts], axis=0)
    total = np.mean([p["total"] for p in parts], axis=0)
    error = np.sqrt(np.sum([p["error_total"] ** 2 for p in parts], axis=0)) / len(parts)
    return cells, second, total, error


def add_early(tables, *, photons, max_path=EARLY_MAX_PATH, progress=True, walked=None):
    r"""Join an early part of ``photons`` photons per (eta, g) to full tables: their short paths, many times over.

    A low albedo's light is the paths of a few transport lengths, and the full walks' 2 x 10^6
    photons hold too few of them: their totals at reduced albedo 0.02-0.1 were up to 2 % off
    adding-doubling at g = 0, 1.8-2.5 of their standard errors (issue 37). Every path up to
    ``max_path`` is cheap to walk. A shipped cell S is two tallies of disjoint sets of the full
    walk's photons, S = late + own: ``own`` the paths that left before the cap (the walk is
    counter-based, so rerunning the shipped seeds capped at ``max_path`` reproduces exactly those
    photons; checked: at the largest absorption, where only short paths count, the remainder
    must vanish) and ``late`` the rest. A new walk of ``photons`` photons on other seeds, whose
    first flight is importance-sampled (``FIRST_FLIGHT_RATES``: at a' = 48 only a photon first
    scattered within 0.01 transport lengths of the surface counts, one in a hundred of a plain
    walk's), estimates the same early part again as ``new``. Each cell becomes

        T = late + w new + (1 - w) own = S + w (new - own),

    unbiased for any w. Per absorption node, w minimises the total's variance,
    w = Cov(S, own) / (Var(own) + Var(new)) with Cov(S, own) = Var(own) - E[late] E[own] / N
    (a photon is late or early, never both): at a' = 0, w = 0, so a medium that absorbs nothing
    still returns exactly all light (late + own is every photon); at a low albedo, w -> 1.
    The file keeps the parts (``early_exitance`` = new, ``early_second``: new's second moments,
    which the identity with the cell at 2a' no longer gives under weights; ``own_exitance``,
    ``early_weight`` = w; the totals' ``early_total``, ``early_error_total``, ``own_total``) so
    that the noise of each follows from the tables (:func:`jsss.transport.profiles.split_relative_variance`).

    ``walked``: the new walk's parts from an earlier run's file (its ``early_*`` arrays, same
    grids, etas and g), to blend again without walking them again.
    """
    if "early_photons" in tables:
        raise SystemExit("these tables already hold an early part; build the full tables again first")
    grid = TableGrid()
    seeds = [int(s) for s in np.atleast_1d(tables["seed"])]
    full = int(tables["photons"])
    runs = max(1, int(round(photons / EARLY_RUN)))
    if walked is not None:
        runs = int(walked["early_photons"]) // EARLY_RUN
    out = dict(tables)
    exitance = tables["exitance"].astype(np.float64)
    total, error = tables["total"].copy(), tables["error_total"].copy()
    early_exitance, early_second, own_exitance = (np.zeros_like(exitance) for _ in range(3))
    early_total, early_error, own_total, weight = (np.zeros_like(total) for _ in range(4))
    tail_per_constant = tail_total_closed_form(grid.absorption, float(tables["max_path"]))
    for i, eta in enumerate(tables["etas"]):
        for j, g in enumerate(tables["gs"]):
            start = time.perf_counter()
            own, _, own_sum, own_error = _early_tables(eta, g, [_table_seed(s, eta, j) for s in seeds],
                                                       full // len(seeds), max_path=max_path, grid=grid)
            late_total = total[i, j] - own_sum
            if abs(late_total[-1]) > 1e-5 * total[i, j, -1]:
                raise SystemExit(f"eta {eta} g {g}: the shipped photons' short paths did not reproduce (at a' = "
                                 f"{grid.absorption[-1]:g} the remainder is {late_total[-1] / total[i, j, -1]:.2e} of "
                                 "the total); the tables were built on another platform or version")
            if walked is None:
                new, new_second, new_total, new_error = _early_tables(
                    eta, g, [_early_seed(k, eta, j) for k in range(runs)], EARLY_RUN, max_path=max_path, grid=grid,
                    first_flight_rates=FIRST_FLIGHT_RATES, early_turn=_early_turn_of(g))
            else:
                new, new_second, new_total, new_error = (np.asarray(walked[key][i, j], np.float64) for key in (
                    "early_exitance", "early_second", "early_total", "early_error_total"))
            covariance = _own_covariance(tables, i, j, late_total, own_sum, own_error, tail_per_constant)
            exitance[i, j], total[i, j], error[i, j], w = _blend(
                exitance[i, j], total[i, j], error[i, j] ** 2, (own, own_sum, own_error),
                (new, new_total, new_error), covariance, grid.absorption)
            early_exitance[i, j], early_second[i, j], own_exitance[i, j] = new, new_second, own
            early_total[i, j], early_error[i, j], own_total[i, j], weight[i, j] = new_total, new_error, own_sum, w
            if progress:
                k = np.searchsorted(grid.absorption, 40.0)
                print(f"eta {eta} g {g}: early {runs * EARLY_RUN:.1e} photons, total at a' = {grid.absorption[k]:.3g} "
                      f"{tables['total'][i, j, k]:.6f} +- {tables['error_total'][i, j, k]:.1e} -> {total[i, j, k]:.6f} "
                      f"+- {error[i, j, k]:.1e} (w {w[k]:.3f}), {time.perf_counter() - start:.0f} s", file=sys.stderr,
                      flush=True)
    out.update(exitance=exitance.astype(np.float32), total=total, error_total=error,
               early_exitance=early_exitance.astype(np.float32), early_second=early_second.astype(np.float32),
               own_exitance=own_exitance.astype(np.float32), early_weight=weight, early_total=early_total,
               early_error_total=early_error, own_total=own_total, early_photons=np.int64(runs * EARLY_RUN),
               early_max_path=np.float64(max_path), early_first_flight_rates=np.asarray(FIRST_FLIGHT_RATES),
               early_turn_fraction=np.array([EARLY_TURN_FRACTION if _early_turn_of(g) else 0.0 for g in tables["gs"]]),
               early_turns=np.int64(EARLY_TURNS))
    return out


def _early_turn_of(g):
    """(fraction, events) of the early turns for the early walks of ``g``, or None."""
    return (EARLY_TURN_FRACTION, EARLY_TURNS) if np.any(np.isclose(g, EARLY_TURN_GS)) else None


BLEND_RAMP = 0.01  # a': the blend weight's onset, see _blend_weight


def _blend_weight(covariance, own_error, new_error, absorption):
    """The early walk's weight w per absorption node: the variance-minimising Cov(S, own) / (Var(own)
    + Var(new)), times a' / (a' + ``BLEND_RAMP``).

    w = 0 at a' = 0 keeps a medium that absorbs nothing returning exactly all light. The
    variance-minimising w is already 0.06 at the first node (a' = 1e-5), and a jump there puts
    w (new - own), noise of a few tenths of a percent, into the slope of every cell in a' at
    sigma_a = 0: it had the exitance near the beam rise with absorption (g 0.8, eta 1). The
    ramp brings the onset's slope to w / 0.01 (new - own), far below the cells' own (their mean
    path, a few transport lengths), and costs nothing where the new walk matters (a' >= 1).
    """
    w = np.clip(covariance / np.maximum(own_error**2 + new_error**2, 1e-300), 0.0, 1.0)
    return w * absorption / (absorption + BLEND_RAMP)


def _blend(cells, total, variance, own_part, new_part, covariance, absorption):
    """Shipped cells, total and the total's variance (S, unblended) joined to the early walk:
    T = S + w (new - own), Var(T) = Var(S) - 2 w Cov(S, own) + w^2 (Var(own) + Var(new)), w of
    :func:`_blend_weight`. ``own_part``, ``new_part``: (cells, total, total's error). Returns
    (cells, total, total's error, w)."""
    own, own_total, own_error = own_part
    new, new_total, new_error = new_part
    w = _blend_weight(covariance, own_error, new_error, absorption)
    return (np.maximum(cells + w[None, :, None] * (new - own), 0.0), total + w * (new_total - own_total),
            np.sqrt(np.maximum(variance - 2 * w * covariance + w**2 * (own_error**2 + new_error**2), 0.0)), w)


def _own_covariance(tables, i, j, late_total, own_sum, own_error, tail_per_constant):
    """Cov(S, own) of a shipped total S = late + own, per absorption node: Var(own) - E[late] E[own] / N."""
    # The late tally's own mean: the modelled tail beyond the full walks' cap is no tally.
    tail = float(tables["tail_mass"][i, j]) * np.sqrt(float(tables["max_path"])) / 2 * tail_per_constant
    late_tallied = np.maximum(late_total - tail, 0.0)
    return own_error**2 - late_tallied * own_sum / int(tables["photons"])


def rewalk_early(tables, gs, *, extra_photons=0, walk=True, progress=True):
    r"""Walk the early part of the ``gs`` rows of tables that hold one again and blend it anew.

    Without ``extra_photons``: the same seeds and photons again, with early turns
    (``EARLY_TURN_FRACTION`` of the scatterings among a photon's first ``EARLY_TURNS`` events
    drawn uniformly over the sphere, :func:`jsss.transport.photon_walk._early_turn`). With it
    (every g at once, so that ``early_photons`` holds for all): ``extra_photons`` more per
    (eta, g) on the next seeds, walked as the row's early part was (turned or not), and pooled
    with it. With ``walk=False``: nothing is walked, the rows are blended again (after a change
    of :func:`_blend_weight`).

    The shipped cells are T = S + w (new - own) (:func:`add_early`); with the full walks' own
    short paths rerun (capped, as there) the blend is undone, S = T - w (new - own), and the
    total's variance before it, Var(S) = Var(T) + 2 w Cov(S, own) - w^2 (Var(own) + Var(new)).
    Then the new early part is blended by its own variance-minimising w. Rows of other g are
    left as they are.
    """
    if "early_photons" not in tables:
        raise SystemExit("--rewalk-gs, --more-early and --reblend need tables with an early part (--early) first")
    if extra_photons and not all(np.any(np.isclose(g, gs)) for g in tables["gs"]):
        raise SystemExit("--more-early adds photons to every g (the file holds one early photon count)")
    grid = TableGrid()
    out = {key: (value.copy() if isinstance(value, np.ndarray) else value) for key, value in tables.items()}
    seeds = [int(s) for s in np.atleast_1d(tables["seed"])]
    full = int(tables["photons"])
    runs = int(tables["early_photons"]) // EARLY_RUN
    extra_runs = round(extra_photons / EARLY_RUN)
    max_path = float(tables["early_max_path"])
    tail_per_constant = tail_total_closed_form(grid.absorption, float(tables["max_path"]))
    fraction = np.asarray(out.get("early_turn_fraction", np.zeros(len(tables["gs"]))), np.float64).copy()
    exitance = out["exitance"].astype(np.float64)
    for j, g in enumerate(tables["gs"]):
        if not np.any(np.isclose(g, gs)):
            continue
        if walk and not extra_runs:
            fraction[j] = EARLY_TURN_FRACTION
        turn = (float(fraction[j]), EARLY_TURNS) if fraction[j] > 0 else None
        for i, eta in enumerate(tables["etas"]):
            start = time.perf_counter()
            own, _, own_sum, own_error = _early_tables(eta, g, [_table_seed(s, eta, j) for s in seeds],
                                                       full // len(seeds), max_path=max_path, grid=grid)
            if not np.allclose(own_sum, tables["own_total"][i, j], rtol=1e-9, atol=1e-15):
                raise SystemExit(f"eta {eta} g {g}: the full walks' short paths did not reproduce the file's own_total")
            w_old = tables["early_weight"][i, j]
            old = [np.asarray(tables[key][i, j], np.float64) for key in
                   ("early_exitance", "early_second", "early_total", "early_error_total")]
            shipped = exitance[i, j] - w_old[None, :, None] * (old[0] - own)
            total_shipped = tables["total"][i, j] - w_old * (old[2] - own_sum)
            covariance = _own_covariance(tables, i, j, total_shipped - own_sum, own_sum, own_error, tail_per_constant)
            variance_shipped = (tables["error_total"][i, j] ** 2 + 2 * w_old * covariance
                                - w_old**2 * (own_error**2 + old[3] ** 2))
            walked = range(runs, runs + extra_runs) if extra_runs else range(runs)
            if walk:
                new, new_second, new_total, new_error = _early_tables(
                    eta, g, [_early_seed(k, eta, j) for k in walked], EARLY_RUN, max_path=max_path, grid=grid,
                    first_flight_rates=FIRST_FLIGHT_RATES, early_turn=turn)
            else:
                new, new_second, new_total, new_error = old
            if walk and extra_runs:  # pool: means weighted by runs, the total's error as a mean's
                a, b = runs / (runs + extra_runs), extra_runs / (runs + extra_runs)
                new, new_second, new_total = a * old[0] + b * new, a * old[1] + b * new_second, a * old[2] + b * new_total
                new_error = np.hypot(a * old[3], b * new_error)
            exitance[i, j], out["total"][i, j], out["error_total"][i, j], w = _blend(
                shipped, total_shipped, variance_shipped, (own, own_sum, own_error), (new, new_total, new_error),
                covariance, grid.absorption)
            out["early_exitance"][i, j], out["early_second"][i, j] = new, new_second
            out["early_total"][i, j], out["early_error_total"][i, j], out["early_weight"][i, j] = new_total, new_error, w
            if progress:
                k = np.searchsorted(grid.absorption, 40.0)
                print(f"eta {eta} g {g}: early part walked again, total at a' = {grid.absorption[k]:.3g} "
                      f"{tables['total'][i, j, k]:.6f} +- {tables['error_total'][i, j, k]:.1e} -> "
                      f"{out['total'][i, j, k]:.6f} +- {out['error_total'][i, j, k]:.1e} (w {w[k]:.3f}), "
                      f"{time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    out.update(exitance=exitance.astype(np.float32), early_turn_fraction=fraction, early_turns=np.int64(EARLY_TURNS),
               early_photons=np.int64((runs + (extra_runs if walk else 0)) * EARLY_RUN))
    return out


def add_views(tables, *, photons, progress=True):
    r"""Add the radiance toward exact view directions (0, 10, ..., 80 degrees outside) for the early part.

    The cones' early part (paths whose last collision lies within ``early_max_path``, the blend
    ``w new + (1 - w) own`` of :func:`add_early`) is where the cone average and the exact
    direction differ: single scattering and the first few orders, whose light has a sharp
    angular and radial structure near the beam. :func:`jsss.transport.view_walk.view_tables`
    estimates that same early part toward each view by next-event estimates, with ``photons``
    photons per (eta, g) and the early walks' first-flight mixture. The file keeps it as
    ``view_radiance`` (eta, g, view, rho, a) with ``view_variance`` (each cell's variance of the
    mean, from 20 independent batches), ``view_cos`` and ``view_photons``;
    :mod:`jsss.transport.profiles` joins it to the cones' late part (the shipped cells less
    their early blend, interpolated to the view).
    """
    if "early_photons" not in tables:
        raise SystemExit("--views needs tables with an early part (--early) first")
    grid = TableGrid()
    shape = tables["early_weight"].shape[:2] + (len(VIEW_DEGREES), grid.rho_edges.size - 1, grid.absorption.size)
    radiance, variance = np.zeros(shape), np.zeros(shape)
    for i, eta in enumerate(tables["etas"]):
        for j, g in enumerate(tables["gs"]):
            start = time.perf_counter()
            out = view_tables(float(eta), float(g), photons=photons, max_path=float(tables["early_max_path"]),
                              seed=_view_seed(eta, j), first_flight_rates=FIRST_FLIGHT_RATES, grid=grid)
            radiance[i, j], variance[i, j] = out["radiance"], out["variance"]
            if progress:
                near = np.searchsorted(grid.rho_edges, 0.3) - 1
                print(f"eta {eta} g {g}: view radiance at 0 degrees, rho' {grid.rho_edges[near]:.2f}, a' 0: "
                      f"{radiance[i, j, 0, near, 0]:.4g} +- {np.sqrt(variance[i, j, 0, near, 0]):.1g}, "
                      f"{time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    out = dict(tables)
    out.update(view_radiance=radiance.astype(np.float32), view_variance=variance.astype(np.float32),
               view_cos=np.cos(np.radians(np.asarray(VIEW_DEGREES))), view_photons=np.int64(photons))
    return out


def build(etas, gs, *, photons, seed, max_path=MAX_PATH, lanes=4096, progress=True):
    grid = TableGrid()
    shape = (len(etas), len(gs))
    exitance = np.zeros(shape + (grid.rho_edges.size - 1, grid.absorption.size, grid.mu_edges.size - 1))
    total, error_total = np.zeros(shape + (grid.absorption.size,)), np.zeros(shape + (grid.absorption.size,))
    lost, tail_mass = np.zeros(shape), np.zeros(shape)
    for i, eta in enumerate(etas):
        for j, g in enumerate(gs):
            start = time.perf_counter()
            records = _walk(eta, g, photons=photons, seed=_table_seed(seed, eta, j), max_path=max_path, lanes=lanes,
                            progress=progress, label=f"eta {eta} g {g}")
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
    for key in ("etas", "exitance", "total", "error_total", "lost", "tail_mass", "early_exitance", "early_second",
                "own_exitance", "early_weight", "early_total", "early_error_total", "own_total", "view_radiance",
                "view_variance"):
        if key in out:
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
    parser.add_argument("--early", type=int, metavar="PHOTONS",
                        help=f"join PHOTONS short paths (up to {EARLY_MAX_PATH:g} transport lengths) per eta and g "
                             "to the full tables of --tables (those of --etas)")
    parser.add_argument("--views", type=int, metavar="PHOTONS",
                        help="add the early part's radiance toward exact view directions (next-event estimates of "
                             "PHOTONS photons per eta and g) to the tables of --tables (those of --etas)")
    parser.add_argument("--tables", type=Path, default=DEFAULT_OUT, help="the full tables --early adds to")
    parser.add_argument("--rewalk-gs", metavar="GS",
                        help="walk the early part of these g (comma-separated) in --tables again, with early turns "
                             f"(the shipped {','.join(str(g) for g in EARLY_TURN_GS)}), and blend it anew")
    parser.add_argument("--more-early", type=int, metavar="PHOTONS",
                        help="add PHOTONS more early photons per eta and g to --tables (next seeds, each row walked "
                             "as before) and blend again")
    parser.add_argument("--reblend", action="store_true",
                        help="blend the early part of --tables again (its walks kept: minutes), after a change of "
                             "the blend's weight")
    parser.add_argument("--walked", type=Path, help="take --early's new walk from this earlier output (its early_* "
                                                    "arrays) instead of walking it again")
    args = parser.parse_args()
    if args.views:
        tables = dict(np.load(args.tables))
        keep = np.flatnonzero(np.isin(np.round(tables["etas"], 6), [round(float(e), 6) for e in args.etas.split(",")]))
        n_etas = tables["etas"].size
        tables = {key: (value[keep] if np.ndim(value) >= 1 and value.shape[0] == n_etas and key != "seed" else value)
                  for key, value in tables.items()}
        tables = add_views(tables, photons=args.views)
    elif args.rewalk_gs:
        tables = rewalk_early(dict(np.load(args.tables)), [float(g) for g in args.rewalk_gs.split(",")])
    elif args.reblend:
        tables = dict(np.load(args.tables))
        tables = rewalk_early(tables, [float(g) for g in tables["gs"]], walk=False)
    elif args.more_early:
        tables = dict(np.load(args.tables))
        tables = rewalk_early(tables, [float(g) for g in tables["gs"]], extra_photons=args.more_early)
    elif args.early or args.walked:
        tables = dict(np.load(args.tables))
        keep = np.flatnonzero(np.isin(np.round(tables["etas"], 6), [round(float(e), 6) for e in args.etas.split(",")]))
        walked = None
        if args.walked:
            walked = dict(np.load(args.walked))
            rows = [int(np.flatnonzero(np.isclose(walked["etas"], e))[0]) for e in tables["etas"][keep]]
            walked = {key: (value[rows] if key.startswith("early_") and np.ndim(value) >= 2 else value)
                      for key, value in walked.items()}
        for key in ("etas", "exitance", "total", "error_total", "lost", "tail_mass"):
            tables[key] = tables[key][keep]
        tables = add_early(tables, photons=args.early or 0, walked=walked)
    elif args.merge:
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
