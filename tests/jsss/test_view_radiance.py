"""The radiance toward a camera's exact direction (issue 37), against a walk that shares no code
with the tables.

The truth is :func:`measure.synth_transport.camera_walk`: NumPy, absorption in the walk,
next-event estimates toward one fixed direction (see its docstring); the tables' view part is
:mod:`jsss.transport.view_walk` (a white walk, absorption by Laplace transform, a random view
azimuth per collision) joined to the cones' late part. The user's call: ``transport.radiance``
with its defaults (the exact direction, ``exact=True``), at eta 1.3 (a table node) and the
camera's cosine.
"""

import itertools

import numpy as np
import pytest

from jsss import Medium, transport
from jsss.transport import profiles
from measure.synth_transport import camera_walk, leaving_reflectance

EDGES = np.array([0.02, 0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2])  # mm; transport length 1 mm


def _walk(sigma_a, g, view_deg, *, photons, seed, batches=8, eta=1.3, edges=EDGES):
    """Mean radiance over each annulus of ``edges`` [1/(mm^2 sr)] and its standard error."""
    rng = np.random.default_rng(seed)
    area = np.pi * np.diff(edges**2)
    means = []
    for _ in range(batches):
        tally = np.zeros(edges.size - 1)

        def add(x, y, weight, tally=tally):
            tally += np.histogram(np.hypot(x, y), edges, weights=weight)[0]

        camera_walk(sigma_a, 1.0, eta, g, view_deg, photons=photons // batches, rng=rng, tally=add)
        means.append(tally / (photons // batches * area))
    means = np.asarray(means)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(batches)


def _model(sigma_a, g, view_deg, *, eta=1.3, edges=EDGES, exact=True):
    """transport.radiance (by default toward the exact direction) averaged over each annulus
    (area-weighted, 16 radii each)."""
    r = np.stack([np.sqrt(np.linspace(a**2, b**2, 33)[1::2]) for a, b in itertools.pairwise(edges)])
    return np.asarray(transport.radiance(Medium(sigma_a, 1.0, eta), r, np.cos(np.radians(view_deg)), g=g,
                                         exact=exact)).mean(-1)


def test_the_independent_walks_fresnel_is_jsss_fresnel():
    """The truth's boundary (angle form) against jsss's (cosine form): the same law, two codes."""
    from jsss.fresnel import fresnel_reflectance

    mu = np.linspace(0.0, 1.0, 201)
    for eta in (1.0, 1.3, 1.6):
        np.testing.assert_allclose(leaving_reflectance(mu, eta), np.asarray(fresnel_reflectance(mu, 1 / eta)),
                                   atol=1e-12)


@pytest.mark.parametrize("sigma_a, g, view_deg", [(0.5, 0.0, 0.0), (0.5, 0.0, 40.0), (0.05, 0.0, 0.0),
                                                  (0.05, 0.5, 40.0), (5.0, 0.0, 0.0)])
def test_radiance_toward_the_exact_direction_matches_an_independent_walk(sigma_a, g, view_deg):
    """Within 0.02-3.2 transport lengths of the beam, albedo' 0.95-0.17, at 0 and 40 degrees:
    every annulus the walk resolves (its standard error under 10 %) within 3 % plus 3 standard
    errors of the walk and the tables together. Measured (2026-12-06): within 2.7 %, most
    within 1 %. The cones' average (``exact=False``, the default before 2026-12-06), toward
    the normal at albedo' 0.67, reads +594, +328, +125, +27, +3 % from 0.02 to 0.8 transport
    lengths (single scattering reaching the cone's slant paths), checked below; at 40 degrees
    within 2.2 %."""
    walk, walk_error = _walk(sigma_a, g, view_deg, photons=400_000, seed=11)
    model = _model(sigma_a, g, view_deg)
    # The tables' own error at each annulus: the view cell's, at the nearest absorption node.
    data = profiles._tables()
    noise = profiles._view_noise_table()[int(np.flatnonzero(np.isclose(data["etas"], 1.3))[0]),
                                            profiles._g_index(g)]
    view = round(view_deg / 10)
    node = int(np.argmin(abs(np.log(np.maximum(data["absorption"], 1e-300) / sigma_a))))
    centres = np.sqrt(EDGES[:-1] * EDGES[1:])
    cells = np.clip(np.searchsorted(data["rho_edges"], centres) - 1, 0, None)
    table_error = np.sqrt(noise[view, cells, node]) * model
    resolved = walk_error < 0.1 * walk
    assert resolved.sum() >= 5
    deviation = (model / walk - 1)[resolved]
    allowed = (0.03 + 3 * np.hypot(walk_error, table_error) / walk)[resolved]
    assert np.all(abs(deviation) < allowed), (deviation.round(3), allowed.round(3))
    if view_deg == 0.0 and sigma_a == 0.5:
        r = np.sqrt(EDGES[2] * EDGES[3])  # 0.1-0.2 transport lengths: the cones' average is far off
        cone = float(np.asarray(transport.radiance(Medium(sigma_a, 1.0, 1.3), r, 1.0, g=g, exact=False)))
        exact = float(np.asarray(transport.radiance(Medium(sigma_a, 1.0, 1.3), r, 1.0, g=g)))
        assert cone > 1.5 * exact


def test_far_from_the_beam_the_light_leaves_obliquely_and_the_normal_reads_it():
    """At eta 1.0, reduced albedo 0.86 (a' 0.158, a table node), 2.6-7.3 transport lengths
    from the beam: light that has travelled that far leaves more obliquely, so the radiance
    along the normal lies below the 0-20.7 degree cone's average (nearer the beam the late
    light rises toward the normal). The tables' view part carries the late light past the top
    cone's centre with its own slope at that radius; one slope pooled over all radii (before
    2026-12-06) read the normal +1.3, +2.4, +3.3, +3.5 % high here against this walk at
    2 x 10^7 photons, and the cones' average +2.2, +2.0, +2.5, +2.5 % (now +1.0, +1.4, +1.8,
    +1.6 %: the top cone's own cells read +0.7 to +2 % there against an analog walk, their
    noise). Checked: the truth is below the cones' average by more than 3 of its errors, and
    the model's mean deviation is within 3 combined errors (the tables' error taken as fully
    correlated across the annuli, as neighbouring annuli share cells)."""
    edges = np.array([2.6, 3.37, 4.37, 5.67, 7.35])                         # transport lengths (mm here)
    sigma_a = float(profiles._tables()["absorption"][22])
    walk, walk_error = _walk(sigma_a, 0.0, 0.0, photons=8_000_000, seed=23, batches=16, eta=1.0, edges=edges)
    exact = _model(sigma_a, 0.0, 0.0, eta=1.0, edges=edges)
    cones = _model(sigma_a, 0.0, 0.0, eta=1.0, edges=edges, exact=False)
    assert np.all(cones - walk > 3 * walk_error), ((cones / walk - 1).round(4), (walk_error / walk).round(4))
    data = profiles._tables()
    cells = np.searchsorted(data["rho_edges"], np.sqrt(edges[:-1] * edges[1:])) - 1
    table_error = np.sqrt(profiles._view_noise_table()[int(np.flatnonzero(data["etas"] == 1.0)[0]), 0, 0, cells, 22])
    weights = 1 / (walk_error / walk) ** 2
    mean_deviation = np.sum(weights * (exact / walk - 1)) / weights.sum()
    mean_error = np.hypot(1 / np.sqrt(weights.sum()), np.sum(weights * table_error) / weights.sum())
    assert abs(mean_deviation) < 3 * mean_error, (mean_deviation, mean_error)
