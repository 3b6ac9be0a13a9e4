"""The transport tables' own Monte Carlo noise, read from the tables (issue 37).

The identity E[e^{-2a'L} 1_cell] = (the cell at 2a') * area gives every cell's variance from the
tables; it is checked against what the walks measured directly (the totals' standard errors,
from the photon weights), against the scatter of fresh, independent walks, and the propagation
into a model value against the interpolation weights it must reduce to."""

import numpy as np
import pytest

from jsss import Medium
from jsss.transport import profiles
from jsss.transport.montecarlo import _params
from jsss.transport.photon_walk import run_walk
from jsss.transport.tables import TableGrid, tabulate, tail_total_closed_form


def test_the_totals_errors_from_the_identity_are_those_the_walks_measured():
    """``error_total`` was computed from each photon's weights (sqrt(mean w^2 - mean^2) / sqrt N,
    for the full walks' paths beyond the early cap and the early walks' paths up to it, in
    quadrature); the identity gets it from the totals alone (their sampled part: the modelled
    tail beyond the full walks' cap is not a tally), at every eta, g and absorption node whose
    double lies in the tables."""
    data = profiles._tables()
    a, photons, early_photons = data["absorption"], int(data["photons"]), int(data["early_photons"])
    tail_constant = data["tail_mass"] * np.sqrt(data["max_path"]) / 2
    sampled = data["total"] - tail_constant[..., None] * tail_total_closed_form(a, data["max_path"])
    early, own, weight = data["early_total"], data["own_total"], data["early_weight"]
    # The early walk's weighted first flights: its totals' second moments from its measured errors.
    early_second = early_photons * data["early_error_total"] ** 2 + early**2
    predicted = sampled * np.sqrt(profiles.split_relative_variance(sampled, early, a, 1.0, photons, early_photons,
                                                                   early_second, own=own, weight=weight))
    inside = 2 * a <= a[-1]
    # Agreement to the interpolation of the total at 2a' (measured: within 0.11 % for one walk).
    # Where the late paths' share falls off (e^{-4a'} beyond the early cap: a' 0.25-1) the late
    # tally's log is curved in log a' and its value at 2a' is interpolated less well (measured:
    # within 3.2 % there); elsewhere within 0.5 %.
    late_share = (sampled - own) / sampled
    steady = inside & ((late_share > 0.5) | (late_share < 0.01))
    np.testing.assert_allclose(predicted[steady], data["error_total"][steady], rtol=5e-3)
    np.testing.assert_allclose(predicted[..., inside], data["error_total"][..., inside], rtol=0.04)
    # At a' = 0 the new walk has no weight (so all light returns, exactly): the full walk's
    # binomial variance R(1 - R) / N, exactly.
    assert np.all(weight[..., 0] == 0)
    np.testing.assert_allclose(predicted[..., 0], np.sqrt(sampled[..., 0] * (1 - sampled[..., 0]) / photons),
                               rtol=1e-9)


@pytest.fixture(scope="module")
def fresh_walks():
    """Two independent absorption-free walks at eta 1.3, g 0 (other seeds than the tables',
    10^5 photons each, capped at 40 transport lengths, which a' >= 0.25 does not feel: e^-10)."""
    eta, photons, max_path = 1.3, 100_000, 40.0
    params = _params([Medium(0.0, 1.0, eta)], [np.inf], g=0.0, eta_above=1 / eta, eta_below=1 / eta, relative=True)
    walks = []
    for seed in (90_001, 90_002):
        records = run_walk(params, n_photons=photons, lanes=1024, max_steps=2**31 - 1, max_path=max_path, seed=seed,
                           progress=False)
        table = tabulate(records.radius, records.path, records.exit_cos, records.side == 1, records.side == 0,
                         grid=TableGrid(), max_path=max_path)
        walks.append((records, table["exitance"]))                             # exitance (rho, a, mu)
    return eta, photons, walks


def _absorption_index(a_prime):
    nodes = TableGrid().absorption
    return int(np.argmin(abs(np.log(nodes[1:] / a_prime)))) + 1


def test_cell_variances_from_the_identity_are_those_of_the_photons_weights(fresh_walks):
    """Per cell of a fresh walk, the variance of its mean from the photons' weights directly,
    (mean w^2 - (mean w)^2) / N, against the identity on that walk's own table: equal up to the
    interpolation to 2a' (measured: median 1.002 / 1.0004, 95 % within 1 / 0.4 %)."""
    _, photons, ((records, cells), _) = fresh_walks
    grid = TableGrid()
    left = records.side == 1
    k = np.clip(np.searchsorted(grid.rho_edges, records.radius[left], side="right") - 1, 0, grid.rho_edges.size - 2)
    m = np.clip(np.searchsorted(grid.mu_edges, records.exit_cos[left], side="right") - 1, 0, grid.mu_edges.size - 2)
    flat, n_cells = k * 8 + m, (grid.rho_edges.size - 1) * 8
    identity = profiles.cell_relative_variance(np.moveaxis(cells, -1, 0), grid.absorption, grid.annulus_area, photons)
    counted = np.bincount(flat, minlength=n_cells).reshape(-1, 8) >= 50
    for a_prime in (1.0, 0.25):
        j = _absorption_index(a_prime)
        weight = np.exp(-grid.absorption[j] * records.path[left])
        first = np.bincount(flat, weight, minlength=n_cells).reshape(-1, 8) / photons
        second = np.bincount(flat, weight**2, minlength=n_cells).reshape(-1, 8) / photons
        direct = (second - first**2) / photons / np.where(counted, first, 1.0) ** 2
        ratio = (identity[:, :, j].T / np.where(counted, direct, 1.0))[counted]
        assert counted.sum() > 200
        assert np.median(ratio) == pytest.approx(1.0, abs=5e-3)
        assert np.percentile(abs(ratio - 1), 95) < 0.03


def test_two_fresh_walks_differ_by_the_sigma_the_shipped_tables_predict(fresh_walks):
    """At a' = 0.25, 1 and 4 the two walks' cells (radius x exit angle) differ by sqrt(2) sigma,
    sigma from the identity on the shipped tables' values for a walk of the fresh walks' photons.
    Cells with at least ~25 photons' worth of variance (Gaussian scatter). Measured: RMS 1.00,
    0.96, 0.96."""
    eta, photons, ((_, first), (_, second)) = fresh_walks
    data = profiles._tables()
    e, g = int(np.flatnonzero(np.isclose(data["etas"], eta))[0]), profiles._g_index(0.0)
    shipped = data["exitance"][e, g].astype(float)                             # (rho, a, mu)
    area = np.pi * np.diff(data["rho_edges"] ** 2)
    relative = np.moveaxis(profiles.cell_relative_variance(np.moveaxis(shipped, -1, 0), data["absorption"], area,
                                                           photons), 0, -1)     # (rho, a, mu), for `photons`
    ratios = []
    for a_prime in (0.25, 1.0, 4.0):
        k = _absorption_index(a_prime)
        scaled = relative[:, k]
        # Tallies, not the float32 underflow far out (1e-35, where the a' = 0 floor holds the variance).
        enough = (scaled < 1 / 25) & (shipped[:, k] > 1e-12 * shipped[:, k].max())
        sigma = shipped[:, k] * np.sqrt(scaled)
        ratios.append((first[:, k] - second[:, k])[enough] / (np.sqrt(2) * sigma[enough]))
    ratios = np.concatenate(ratios)
    assert ratios.size > 400
    # RMS of ~550 unit normals: 1 +- 0.03 (the three a' are correlated: about 1 +- 0.05).
    assert np.sqrt(np.mean(ratios**2)) == pytest.approx(1.0, abs=0.15)
    assert abs(np.mean(ratios)) < 0.2


@pytest.mark.parametrize("cos_exit", [None, 1.0])
def test_a_model_value_at_a_node_carries_its_cells_error_and_eta_mixes_tables_in_quadrature(cos_exit):
    """At eta on a table node, radius at an annulus's log-centre and a' on a node, the
    interpolation weights are (0, 1, 0, 0): the model's relative error is the cell's own (the
    exit-angle bin toward the camera, or the cells summed over angles for exitance). Halfway
    between two eta nodes Catmull-Rom weighs (-1, 9, 9, -1)/16: the variances add with those
    weights squared."""
    data = profiles._tables()
    grid, j = TableGrid(), profiles._g_index(0.5)
    raw = data["exitance"][:, j].astype(float)                                  # (eta, rho, a, mu)
    early, second, own = (data[key][:, j].astype(float) for key in ("early_exitance", "early_second", "own_exitance"))
    if cos_exit is None:
        raw, early, second, own = (x.sum(-1, keepdims=True)[:, None, ..., 0] for x in (raw, early, second, own))
        cells = profiles.split_relative_variance(raw, early, grid.absorption, grid.annulus_area, int(data["photons"]),
                                                 int(data["early_photons"]), second, own=own,
                                                 weight=data["early_weight"][:, j, None, None, :])[:, 0]
        shipped = profiles._noise_tables()["exitance"][:, j, 0]
    else:
        # Toward the normal: the top cone's late part (the cell less its early blend), carried
        # past the cone's centre by its slope at that radius, and the view walk's early part:
        # independent walks, their variances added, with the slope's own noise (``extra``).
        assert profiles._exit_bins(cos_exit, exact=True) == [(0, 1.0)]
        w = data["early_weight"][:, j, None, :]
        late = np.maximum(raw[..., -1] - (w * early[..., -1] + (1 - w) * own[..., -1]), 0.0)
        late = late / (np.pi * (1 - data["mu_edges"][-2] ** 2))
        [(top, factor)], extra = profiles._late_view_mix(data, profiles._late_radiance(data))[0]
        factor, extra = factor[:, j], extra[:, j]                                  # (eta, rho, a)
        assert top == 7 and np.all(abs(factor - 1) < 0.1)
        view, view_variance = (data[key][:, j, 0].astype(float) for key in ("view_radiance", "view_variance"))
        variance = (profiles.cell_relative_variance(late, grid.absorption, grid.annulus_area, int(data["photons"]))
                    * (factor * late) ** 2 + extra * late**2 + view_variance)
        late = factor * late
        with np.errstate(divide="ignore", invalid="ignore"):
            cells = np.where((late + view > 0) & (variance > 0), np.minimum(variance / (late + view) ** 2, 1.0), 1.0)
        shipped = profiles._view_noise_table()[:, j, 0]
    np.testing.assert_allclose(shipped, cells, rtol=1e-10)
    k, rho_index = 21, np.array([20, 30, 40])                                   # a' = 0.01; rho' 0.046, 0.32, 2.2
    centres = np.sqrt(grid.rho_edges[rho_index] * grid.rho_edges[rho_index + 1])
    medium = Medium(grid.absorption[k] * 2.0, 2.0, 1.3)
    fixed = profiles.fixed_slice(1.3, g=0.5, cos_exit=cos_exit)
    noise = profiles.noise_slice(1.3, g=0.5, cos_exit=cos_exit)
    error = np.asarray(profiles.slice_relative_error(fixed, noise, medium, centres / 2.0))
    np.testing.assert_allclose(error, np.sqrt(cells[3, rho_index, k]), rtol=1e-6)
    mixed = np.asarray(profiles.noise_slice(1.35, g=0.5, cos_exit=cos_exit).log_rows)[0]
    by_hand = np.tensordot(np.array([1, 81, 81, 1]) / 256, cells[2:6], axes=1)
    np.testing.assert_allclose(np.exp(mixed), by_hand, rtol=1e-9)


def _capped_walk_tables(runs, photons, cap):
    """``tabulate`` of walks capped at ``cap`` transport lengths, one per (params, seed) in ``runs``."""
    grid = TableGrid()
    tables = []
    for params, seed in runs:
        records = run_walk(params, n_photons=photons, lanes=1024, max_steps=2**31 - 1, max_path=cap, seed=seed)
        tables.append(tabulate(records.radius, records.path, records.exit_cos, records.side == 1,
                               records.side == 0, grid=grid, max_path=cap, model_tail=False, weight=records.weight))
    return tables


def _assert_totals_and_cells_agree(before, after, photons, cell_nodes):
    """Two walks of one medium agree: totals within 4 combined errors at every absorption node;
    the radius x exit-angle cells both resolve (errors below 20 %) at the nodes ``cell_nodes``
    within 5, with an RMS z of 1 (+-0.25)."""
    grid = TableGrid()
    z = (after["total"] - before["total"]) / np.hypot(after["error_total"], before["error_total"])
    assert np.max(np.abs(z)) < 4, z
    for j in (_absorption_index(a) for a in cell_nodes):
        errors = [np.sqrt(np.maximum(t["second"][:, j] / grid.annulus_area[:, None] - t["exitance"][:, j] ** 2, 0)
                          / photons) for t in (before, after)]
        resolved = (errors[0] < 0.2 * before["exitance"][:, j]) & (errors[1] < 0.2 * after["exitance"][:, j])
        assert resolved.sum() > 50, resolved.sum()
        cell_z = (after["exitance"][:, j] - before["exitance"][:, j]) / np.hypot(*errors)
        assert np.max(np.abs(cell_z[resolved])) < 5
        assert np.sqrt(np.mean(cell_z[resolved] ** 2)) == pytest.approx(1.0, abs=0.25), (resolved.sum(), cell_z[resolved])


def test_an_importance_sampled_first_flight_keeps_the_tables_and_sharpens_a_low_albedo():
    """The tables' early walks draw the first free path from a mixture of faster exponentials and
    weigh it (``photon_walk._first_flight``). Against a plain walk of the same photons (other
    seeds), capped at 4 transport lengths as the early walks are, at eta 1.3: the totals agree
    within 4 combined standard errors at every absorption node, the cells within 5 with an RMS z
    of 1 (+-0.25), and at a' = 40-1000 (reduced albedo 0.024-0.001) the weighted
    walk's error is at least 3 times smaller (measured: 4.5-12.6x; largest |z| of the totals
    1.7). The price: at a' <= 0.1 its error is 1.3x the plain walk's (weights up to 2)."""
    import jax.numpy as jnp

    eta, photons, cap = 1.3, 200_000, 4.0
    grid = TableGrid()
    params = _params([Medium(0.0, 1.0, eta)], [np.inf], g=0.0, eta_above=1 / eta, eta_below=1 / eta, relative=True)
    weighted = params + (jnp.asarray(1.0), jnp.asarray([1.0, 1.0, 1.0, 10.0, 100.0, 1000.0]))
    plain, sampled = _capped_walk_tables([(params, 90_011), (weighted, 90_012)], photons, cap)
    # Cells at a' = 1 and 10 (measured: 223 and 90 resolved, RMS z 1.02 and 1.08).
    _assert_totals_and_cells_agree(plain, sampled, photons, (1.0, 10.0))
    high = grid.absorption >= 40
    assert np.all(plain["error_total"][high] / plain["total"][high]
                  > 3 * sampled["error_total"][high] / sampled["total"][high])


def test_an_early_turn_weighs_its_cosines_back_to_henyey_greenstein():
    """``photon_walk._early_turn`` draws a fraction of turns uniformly over the sphere and weighs
    every turn by p_HG / q: over a fine grid of u, the weighted share below each cosine is HG's
    own cumulative distribution, the weights stay within 1 / (1 - fraction), and a quarter of
    the turns at g = 0.9 go back (cosine below 0) where HG sends 2.3 %."""
    import jax.numpy as jnp

    from jsss.transport.photon_walk import _early_turn

    g, fraction = 0.9, 0.35
    u = (np.arange(2_000_000) + 0.5) / 2_000_000
    cosines, weights = (np.asarray(v) for v in _early_turn(jnp.asarray(g), jnp.asarray(u), jnp.asarray(fraction)))
    assert weights.max() <= 1 / (1 - fraction) + 1e-12
    for c in (-0.9, -0.5, 0.0, 0.5, 0.9, 0.99):
        hg_cdf = (1 - g**2) / (2 * g) * ((1 + g**2 - 2 * g * c) ** -0.5 - 1 / (1 + g))
        assert np.mean(weights * (cosines < c)) == pytest.approx(hg_cdf, rel=2e-3, abs=1e-5), c
    back = (1 - g**2) / (2 * g) * ((1 + g**2) ** -0.5 - 1 / (1 + g))
    assert back == pytest.approx(0.0229, abs=1e-4)
    assert np.mean(cosines < 0) == pytest.approx(fraction / 2 + (1 - fraction) * back, rel=1e-3)


def test_early_turns_keep_the_tables_and_sharpen_a_low_albedo_at_g_09():
    """The early walks of g 0.5, 0.8 and 0.9 also draw the scatterings among a photon's first 3 events
    from HG mixed with the uniform sphere (35 %), and weigh them. Against the same walk without
    them (first flights weighted in both; other seeds), at eta 1.3, g 0.9, capped at 4 transport
    lengths: the totals agree within 4 combined standard errors at every absorption node, the
    cells at a' = 1 and 4 within 5 with an RMS z of 1 (+-0.25; measured 141 and 119 cells, 0.87
    and 0.92), and at a' = 10-160 (reduced albedo 0.09-0.006) the turned walk's error is at
    least 2 times smaller (measured 2.9-3.5x; largest |z| of the totals 1.7)."""
    import jax.numpy as jnp

    eta, photons, cap = 1.3, 200_000, 4.0
    grid = TableGrid()
    params = _params([Medium(0.0, 1.0, eta)], [np.inf], g=0.9, eta_above=1 / eta, eta_below=1 / eta, relative=True)
    plain = params + (jnp.asarray(1.0), jnp.asarray([1.0, 1.0, 1.0, 10.0, 100.0, 1000.0]))
    turned = plain + (jnp.asarray(0.35), jnp.asarray(3, jnp.int32))
    before, after = _capped_walk_tables([(plain, 90_021), (turned, 90_022)], photons, cap)
    _assert_totals_and_cells_agree(before, after, photons, (1.0, 4.0))
    low = (grid.absorption >= 10) & (grid.absorption <= 160)
    assert np.all(before["error_total"][low] / before["total"][low]
                  > 2 * after["error_total"][low] / after["total"][low])
