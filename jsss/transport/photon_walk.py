r"""The photon random walk engine: one collision per lane per step, finished lanes refilled.

GPU Monte Carlo codes keep every lane busy: when a photon leaves, is absorbed or reaches
its cap, its lane starts the next photon at once. A ``vmap`` of one ``while_loop`` per
photon instead runs every lane until the batch's longest walk ends; at albedo 0.999 that
wasted 95-99 % of the work (issue 18). Here the state of ``lanes`` photons advances one
event (a free flight ending in a collision or at a boundary) per step; a finished photon's
record is written at its photon index and the lane takes the next index. Runs advance in
jitted chunks of steps, so Python sees progress between them and, once every photon has
been issued, moves the survivors into fewer lanes (fewer wasted steps while the longest
walks drain).

Random numbers are counter-based: event ``k`` of photon ``i`` draws its four uniforms from
two Threefry-2x32-20 blocks keyed by the seed with counters ``(i, 2k)`` and ``(i, 2k + 1)``:
``jax.extend.random.threefry_2x32``, the generator behind ``jax.random`` (its known answers
from Random123 are tested), applied to our own counters: no key splitting per event. A
photon's path therefore depends only on the seed and its index, not on the lane count or
the order in which lanes finish: a seed reproduces a run bit for bit whatever ``lanes`` is.

The physics (per event): free path :math:`s = -\ln(1-u)/\sigma_t` in the photon's layer;
if the boundary is nearer, the photon moves to it and is reflected with the exact Fresnel
probability for its angle (total internal reflection included) or crosses (Snell) into the
next layer or leaves the stack. Otherwise it collides: its weight is multiplied by the
albedo :math:`\sigma_s/\sigma_t` (absorption by weight), it scatters by Henyey-Greenstein,
and below weight 1e-4 Russian roulette keeps one photon in ten at ten times the weight.
An optional tenth entry of ``params`` (rates, after the start cosine) draws each photon's first
free path from a mixture of faster exponentials, with its importance weight
(:func:`_first_flight`): the transport tables' early walks use it to sample the short paths of
a strongly absorbing medium. Optional eleventh and twelfth entries (a fraction, a count K) draw
the direction of the scatterings among a photon's first K events from HG mixed with the uniform
sphere (:func:`_early_turn`): the same walks use them where the phase function is peaked
forward, whose low-albedo light needs an early turn back.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend.random import threefry_2x32

from ..fresnel import fresnel_reflectance

__all__ = ["WalkRecords", "run_walk", "sample_henyey_greenstein", "turn_cos_sin"]

# Record columns, one row per photon.
_RADIUS, _WEIGHT, _SIDE, _PATH, _EXIT_COS, _PHOTON, _COLUMNS = 0, 1, 2, 3, 4, 5, 6


class WalkRecords(NamedTuple):
    """One row per photon, in photon-index order.

    ``radius`` [mm] where it left (0 if it did not); ``weight`` it carried out (0 if it did
    not leave); ``side``: 0 still walking at the cap (lost), 1 left through the top, 2 left
    through the bottom after scattering, 3 absorbed (roulette), 4 left through the bottom
    without a collision; ``path`` [mm] the total length travelled inside; ``exit_cos`` the
    cosine of its direction to the normal *outside*, after refraction (0 if it did not leave).
    """

    radius: np.ndarray
    weight: np.ndarray
    side: np.ndarray
    path: np.ndarray
    exit_cos: np.ndarray
    seconds: float
    steps: int


def sample_henyey_greenstein(g, xi):
    r"""Cosine of the scattering angle from the HG distribution (inverse CDF); ``g = 0`` isotropic."""
    small = jnp.abs(g) < 1e-6
    safe_g = jnp.where(small, 0.5, g)
    frac = (1 - safe_g**2) / (1 - safe_g + 2 * safe_g * xi)
    cos_hg = (1 + safe_g**2 - frac**2) / (2 * safe_g)
    return jnp.clip(jnp.where(small, 2 * xi - 1, cos_hg), -1.0, 1.0)


def turn_cos_sin(u):
    r""":math:`(\cos 2\pi u, \sin 2\pi u)` for ``u`` in [0, 1], by polynomials, not ``cos``/``sin``.

    XLA:CPU evaluates float64 ``cos`` and ``sin`` one element at a time: they were two thirds
    of an event's cost (103 of 151 ns per lane on one core). Here the angle is split into
    the nearest quarter turn :math:`m \pi/2` and a rest :math:`|r| \le \pi/4`, the rest
    goes through Taylor polynomials to :math:`r^{15}` and :math:`r^{16}` (truncation below
    1e-16 at :math:`\pi/4`), and the quarter turn swaps and negates the pair, exactly. Plain
    arithmetic that XLA vectorises; accurate to a few ulp (tested against ``numpy``).
    """
    quarters = 4 * u
    m = jnp.round(quarters)
    r = (quarters - m) * (jnp.pi / 2)
    r2 = r * r
    sin_r, cos_r = 1.0 / 1307674368000, 1.0 / 20922789888000  # 1/15!, 1/16!
    for k in range(13, 0, -2):  # Horner: sin r / r = sum (-1)^j r^2j / (2j+1)!
        sin_r = 1.0 / math.factorial(k) - r2 * sin_r
    for k in range(14, -1, -2):
        cos_r = 1.0 / math.factorial(k) - r2 * cos_r
    sin_r = r * sin_r
    quarter = m.astype(jnp.int32) % 4
    odd = (quarter == 1) | (quarter == 3)
    cos_t, sin_t = jnp.where(odd, sin_r, cos_r), jnp.where(odd, cos_r, sin_r)
    return (jnp.where((quarter == 1) | (quarter == 2), -cos_t, cos_t),
            jnp.where((quarter == 2) | (quarter == 3), -sin_t, sin_t))


def _scatter(ux, uy, uz, cos_theta, u_phi):
    """Rotate the direction (ux, uy, uz) by polar angle acos(cos_theta) and azimuth 2 pi u_phi."""
    sin_theta = jnp.sqrt(jnp.maximum(1 - cos_theta**2, 0.0))
    cos_phi, sin_phi = turn_cos_sin(u_phi)
    near_pole = jnp.abs(uz) > 0.99999
    denom = jnp.sqrt(jnp.maximum(1 - uz**2, 1e-300))
    nx = sin_theta * (ux * uz * cos_phi - uy * sin_phi) / denom + ux * cos_theta
    ny = sin_theta * (uy * uz * cos_phi + ux * sin_phi) / denom + uy * cos_theta
    nz = -sin_theta * cos_phi * denom + uz * cos_theta
    px, py, pz = sin_theta * cos_phi, sin_theta * sin_phi, jnp.sign(uz) * cos_theta
    return jnp.where(near_pole, px, nx), jnp.where(near_pole, py, ny), jnp.where(near_pole, pz, nz)


class _Lane(NamedTuple):
    # Position and direction one array per component (structure of arrays): XLA fuses an
    # event into one loop over the lanes, where (lanes, 3) arrays cost stacks and copies.
    x: jax.Array          # mm
    y: jax.Array
    z: jax.Array
    ux: jax.Array
    uy: jax.Array
    uz: jax.Array
    weight: jax.Array
    side: jax.Array       # int32, as in WalkRecords
    exit_r: jax.Array
    exit_cos: jax.Array
    path: jax.Array
    steps: jax.Array      # int32 events so far
    collided: jax.Array   # bool
    layer: jax.Array      # int32
    photon: jax.Array     # int32 photon index; == n_photons: idle lane


def _fresh(photon, dtype, cos_start=1.0):
    """A photon just inside the top at the origin, travelling down at ``cos_start`` to the normal
    (1: a beam along the normal; less: an oblique beam after refraction, tilted towards +x)."""
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)
    cos_start = jnp.asarray(cos_start, dtype)
    sin_start = jnp.sqrt(jnp.maximum(1 - cos_start**2, 0.0))
    return _Lane(zero, zero, zero, sin_start, zero, cos_start, one, jnp.int32(0), zero, zero, zero, jnp.int32(0),
                 jnp.bool_(False), jnp.int32(0), photon)


def _start_cosine(params):
    """The optional ninth entry of ``params``: the cosine at which photons start inside (default 1)."""
    return params[8] if len(params) > 8 else 1.0


def _first_flight(u_path, sigma_t, rates):
    r"""The first free path drawn from a mixture of exponentials, and its importance weight.

    ``rates`` (K,) multiply ``sigma_t``; each is drawn with probability 1/K (a rate listed
    twice, twice as often). The mixture :math:`q(s) = \frac1K\sum_k r_k\sigma_t e^{-r_k\sigma_t s}`
    puts the first collision near the surface far more often than :math:`p(s) = \sigma_t
    e^{-\sigma_t s}` does, where a strongly absorbing medium's light comes from; the weight
    :math:`p/q` (for a flight that reaches a boundary at ``d`` instead, the ratio of the two
    survival probabilities) keeps every tally unbiased. With a rate of 1 among them the weight is
    at most K over its count (defensive mixing). ``u_path`` picks the rate and, rescaled, the path.
    """
    k = rates.shape[0]
    scaled = u_path * k
    pick = jnp.minimum(jnp.floor(scaled), k - 1)
    u = scaled - pick                  # uniform in (0, 1) again, never 0 (u_path is (word + 1/2) 2^-32)
    rate = _at_layer(rates, pick.astype(jnp.int32))
    s = -jnp.log(u) / (sigma_t * rate)

    def inverse_mixture(length, factors):  # k / sum_i factors_i e^{-(r_i - 1) sigma_t length}
        return 1.0 / (sum(factors[i] * jnp.exp(-(rates[i] - 1) * sigma_t * length) for i in range(k)) / k)

    weight = functools.partial(inverse_mixture, factors=rates)  # p / q at a collision after ``length``
    survival = functools.partial(inverse_mixture, factors=[1.0] * k)  # the survival ratio at a boundary
    return s, weight, survival


def _henyey_greenstein_density(g, cos_theta):
    r"""The HG density of the scattering cosine, :math:`\frac{1 - g^2}{2 (1 + g^2 - 2 g \mu)^{3/2}}` (integrates to 1 over [-1, 1])."""
    return (1 - g**2) / (2 * (1 + g**2 - 2 * g * cos_theta) ** 1.5)


def _early_turn(g, u_theta, fraction):
    r"""The cosine of an early scattering, drawn from :math:`q = (1 - \beta) p_\mathrm{HG} + \beta / 2`, and its weight :math:`p_\mathrm{HG} / q`.

    At g = 0.9 a photon scatters back (cosine below 0) once in 44, and a strongly absorbing
    medium returns light almost only through such a turn within its first collisions, near the
    surface (where the first flight's mixture puts the first one). With a fraction
    :math:`\beta` of the early turns drawn uniformly over the sphere, about :math:`\beta / 2`
    of them turn back; the weight, at most :math:`1 / (1 - \beta)` per turn (defensive
    mixing), keeps every tally unbiased. ``u_theta`` picks the component and, rescaled, the
    cosine; at g = 0 the weight is 1.
    """
    uniform = u_theta < fraction
    u_uniform = u_theta / jnp.where(fraction > 0, fraction, 1.0)
    u_hg = jnp.clip((u_theta - fraction) / (1 - fraction), 0.0, 1.0)
    cos_theta = jnp.where(uniform, jnp.clip(2 * u_uniform - 1, -1.0, 1.0), sample_henyey_greenstein(g, u_hg))
    density = _henyey_greenstein_density(g, cos_theta)
    return cos_theta, density / ((1 - fraction) * density + fraction / 2)


def _event_words(key, photon, steps):
    """The four random uint32 words of event ``steps`` of ``photon``: (path, turn, phi, roulette).

    Threefry-2x32-20 blocks with counters ``(photon, 2 steps)`` and ``(photon, 2 steps + 1)``,
    keyed by ``key`` (a pair of uint32). ``threefry_2x32`` hashes the first half of its count
    with the second half, so its words come out as x0, x0', x1, x1'.
    """
    photon, event = jnp.asarray(photon).astype(jnp.uint32), 2 * jnp.asarray(steps).astype(jnp.uint32)
    x0, x0_next, x1, x1_next = threefry_2x32(key, jnp.stack([photon, photon, event, event + 1]))
    return jnp.stack([x0, x1, x0_next, x1_next])


def _at_layer(values, layer):
    """``values[layer]`` for a per-layer array of static length, as selects, not a gather.

    XLA:CPU gathers cost about 40 times the same arithmetic; under the lanes' vmap every
    ``values[layer]`` is one, seven per event. A chain of ``where`` over the few layers reads
    the same numbers.
    """
    if values.shape[0] > 8:  # a long chain of selects would cost more than the gather
        return values[layer]
    picked = values[0]
    for k in range(1, values.shape[0]):
        picked = jnp.where(layer == k, values[k], picked)
    return picked


def _event(lane: _Lane, key, params) -> _Lane:
    """Advance one lane by one event (a collision or a boundary)."""
    sigma_t, albedo, g, tops, bottoms, index, eta_above, eta_below = params[:8]
    n_layers = sigma_t.shape[0]
    layer = lane.layer
    dtype = lane.z.dtype
    # Uniforms in (0, 1) from 32 bits: a free path is cut at -ln(2^-33) = 23 mean free paths
    # (probability e^-23), far below any tally's noise. A boundary hit uses u_turn for
    # Fresnel; a collision uses it for the scattering angle (the two never meet in one event).
    words = _event_words(key, lane.photon, lane.steps)
    u_path, u_turn, u_phi, u_roulette = (words.astype(dtype) + 0.5) * (2.0**-32)
    u_fresnel = u_theta = u_turn
    s = -jnp.log(u_path) / _at_layer(sigma_t, layer)
    importance = len(params) > 9  # static: an optional tenth entry, the first flight's rates
    if importance:
        first = lane.steps == 0
        s_first, first_weight, first_survival = _first_flight(u_path, _at_layer(sigma_t, layer), params[9])
        s = jnp.where(first, s_first, s)
    dz = lane.uz
    to_top = jnp.where(dz < 0, (lane.z - _at_layer(tops, layer)) / jnp.where(dz < 0, -dz, 1.0), jnp.inf)
    to_bottom = jnp.where(dz > 0, (_at_layer(bottoms, layer) - lane.z) / jnp.where(dz > 0, dz, 1.0), jnp.inf)
    to_boundary = jnp.minimum(to_top, to_bottom)
    hits = s >= to_boundary
    up = to_top <= to_bottom
    step = jnp.where(hits, to_boundary, s)
    x, y = lane.x + lane.ux * step, lane.y + lane.uy * step
    z = jnp.where(hits, jnp.where(up, _at_layer(tops, layer), _at_layer(bottoms, layer)), lane.z + dz * step)
    # Boundary: Fresnel reflection or transmission (with refraction into the next layer).
    neighbour = jnp.where(up, layer - 1, layer + 1)
    outside = (neighbour < 0) | (neighbour >= n_layers)
    n1 = _at_layer(index, layer)
    n2 = jnp.where(neighbour < 0, eta_above,
                   jnp.where(neighbour >= n_layers, eta_below, _at_layer(index, neighbour)))
    reflects = u_fresnel < fresnel_reflectance(jnp.abs(dz), n2 / n1)
    leaves = hits & ~reflects & outside
    crosses = hits & ~reflects & ~outside
    ratio = n1 / n2
    cos_t = jnp.sqrt(jnp.maximum(1 - ratio**2 * (1 - dz**2), 0.0))
    # Collision: absorb by weight, scatter by HG, roulette below 1e-4.
    cos_theta = sample_henyey_greenstein(_at_layer(g, layer), u_theta)
    turning = len(params) > 10  # static: optional 11th and 12th entries, the early turns' uniform fraction and count
    if turning:
        early_turn = (lane.steps < params[11]) & ~hits
        cos_early, turn_weight = _early_turn(_at_layer(g, layer), u_theta, params[10])
        cos_theta = jnp.where(early_turn, cos_early, cos_theta)
    sx, sy, sz = _scatter(lane.ux, lane.uy, dz, cos_theta, u_phi)
    collided_weight = lane.weight * _at_layer(albedo, layer)
    low = collided_weight < 1e-4
    collided_weight = jnp.where(low, jnp.where(u_roulette < 0.1, collided_weight * 10, 0.0), collided_weight)

    def turned(component, refracted, mirrored, scattered):  # reflected, refracted, straight on, or scattered
        return jnp.where(hits, jnp.where(reflects, mirrored, jnp.where(crosses, refracted, component)), scattered)

    new_ux = turned(lane.ux, lane.ux * ratio, lane.ux, sx)
    new_uy = turned(lane.uy, lane.uy * ratio, lane.uy, sy)
    new_uz = turned(dz, jnp.sign(dz) * cos_t, -dz, sz)
    new_weight = jnp.where(hits, lane.weight, collided_weight)
    if importance:
        factor = jnp.where(hits, first_survival(to_boundary), first_weight(s))
        new_weight = jnp.where(first, new_weight * factor, new_weight)
    if turning:
        new_weight = jnp.where(early_turn, new_weight * turn_weight, new_weight)
    side = jnp.where(leaves, jnp.where(up, 1, 2), jnp.where(new_weight == 0, 3, 0)).astype(jnp.int32)
    return _Lane(x, y, z, new_ux, new_uy, new_uz, new_weight, side,
                 jnp.where(leaves, jnp.hypot(x, y), lane.exit_r),
                 jnp.where(leaves, cos_t, lane.exit_cos), lane.path + step, lane.steps + 1,
                 lane.collided | ~hits, jnp.where(crosses, neighbour, layer), lane.photon)


def _record(lane: _Lane):
    side = jnp.where((lane.side == 2) & ~lane.collided, 4, lane.side)
    left = (side == 1) | (side == 2) | (side == 4)
    dtype = lane.weight.dtype
    return jnp.stack([lane.exit_r, jnp.where(left, lane.weight, 0.0), side.astype(dtype), lane.path,
                      jnp.where(left, lane.exit_cos, 0.0), lane.photon.astype(dtype)])


_CHUNK = 64  # refills per jitted call: progress and the survivor compaction happen between calls
_EVENTS_PER_REFILL = 8
_CAPACITY = 1 << 16  # rows of records one call may return


@jax.jit
def _advance(lanes: _Lane, next_id, issue_limit, n_photons, key, params, max_steps, max_path):
    """Advance every lane by ``_CHUNK`` refills of up to ``_EVENTS_PER_REFILL`` events each;
    finished photons are appended to ``records``.

    A lane whose photon finished, and an idle lane (photon index ``n_photons``), takes the
    next index below ``issue_limit``. The caller keeps ``issue_limit - next_id + lanes <=
    _CAPACITY``, so every photon that can finish during the call has a row. Everything that
    varies between runs is an argument, not a captured constant: one compilation per lane
    count serves every medium, seed and run size.
    """
    dtype = params[0].dtype

    def one_step(_, carry):
        lanes, records, count, next_id = carry
        active = lanes.photon < n_photons

        def event(_, lanes):
            walking = (lanes.photon < n_photons) & (lanes.side == 0) & (lanes.steps < max_steps) & (
                lanes.path < max_path)
            moved = jax.vmap(_event, in_axes=(0, None, None))(lanes, key, params)
            return jax.tree.map(lambda new, old: jnp.where(walking.reshape((-1,) + (1,) * (new.ndim - 1)), new, old),
                                moved, lanes)

        # A few events between refills: recording and refilling cost as much as an event.
        moved = jax.lax.fori_loop(0, _EVENTS_PER_REFILL, event, lanes, unroll=False)
        finished = active & ((moved.side != 0) | (moved.steps >= max_steps) | (moved.path >= max_path))
        slot = count + jnp.cumsum(finished, dtype=jnp.int32) - 1
        records = records.at[jnp.where(finished, slot, _CAPACITY)].set(jax.vmap(_record)(moved), mode="drop")
        count = count + jnp.sum(finished, dtype=jnp.int32)
        wants = finished | ~active
        issued = next_id + jnp.cumsum(wants, dtype=jnp.int32) - 1
        new_photon = jnp.where(issued < issue_limit, issued, n_photons)
        fresh = jax.vmap(_fresh, in_axes=(0, None, None))(new_photon, dtype, _start_cosine(params))
        lanes = jax.tree.map(lambda f, m: jnp.where(wants.reshape((-1,) + (1,) * (f.ndim - 1)), f, m), fresh, moved)
        next_id = jnp.minimum(next_id + jnp.sum(wants, dtype=jnp.int32), issue_limit)
        return lanes, records, count, next_id

    records = jnp.zeros((_CAPACITY, _COLUMNS), dtype)
    lanes, records, count, next_id = jax.lax.fori_loop(0, _CHUNK, one_step, (lanes, records, jnp.int32(0), next_id))
    return lanes, records, count, next_id, jnp.sum(lanes.photon < n_photons, dtype=jnp.int32)


def run_walk(params, *, n_photons: int, lanes: int = 4096, max_steps: int = 2000, max_path=np.inf, seed: int = 0,
             progress: bool = False, label: str = "random_walk") -> WalkRecords:
    """Walk ``n_photons`` photons through the stack described by ``params``; one record each.

    ``params`` = (sigma_t, albedo, g, tops, bottoms, index, eta_above, eta_below), per layer
    arrays of one dtype (see :mod:`jsss.transport.montecarlo`), optionally followed by the cosine at which
    photons start inside (an oblique beam after refraction; default 1, along the normal) and by
    the first flight's rates (:func:`_first_flight`; each record's weight then carries the
    importance weight) and by the early turns' uniform fraction and count of events
    (:func:`_early_turn`, weighted too). A photon still inside after ``max_steps`` events or
    ``max_path`` [mm] of path is recorded as lost (side 0). With ``progress`` a line per chunk goes to stderr (a script's choice: the
    library prints nothing by default).
    """
    dtype = params[0].dtype
    n_photons = int(n_photons)
    if n_photons >= 2**31 - 1:
        raise ValueError(f"run_walk(n_photons=...) must be below 2**31 - 1; got {n_photons}. Run several seeds.")
    lanes = int(max(1, min(lanes, n_photons, _CAPACITY // 2)))
    key = (jnp.uint32(seed & 0xFFFFFFFF), jnp.uint32((seed >> 32) & 0xFFFFFFFF))
    count = jnp.int32(n_photons)
    max_steps, max_path = jnp.int32(max_steps), jnp.asarray(max_path, dtype)
    shown = bool(progress)
    state = jax.vmap(_fresh, in_axes=(0, None, None))(jnp.full(lanes, n_photons, jnp.int32), dtype,
                                                      _start_cosine(params))  # all idle
    next_id, issued, done = jnp.int32(0), 0, 0
    start, steps, chunks = time.perf_counter(), 0, []
    while True:
        width = state.photon.shape[0]
        limit = min(n_photons, issued + _CAPACITY - width)
        state, records, finished, next_id, active = _advance(state, next_id, jnp.int32(limit), count, key, params,
                                                             max_steps, max_path)
        steps += _CHUNK * _EVENTS_PER_REFILL
        finished, issued, active = int(finished), int(next_id), int(active)
        chunks.append(np.asarray(records[:finished]))
        done += finished
        if shown:
            print(f"\r{label}: {done}/{n_photons} photons", end="", file=sys.stderr, flush=True)
        if done >= n_photons:
            break
        # Every photon issued: move the survivors into fewer lanes so the drain costs less.
        if issued >= n_photons and width >= 64 and active <= width // 8:
            order = jnp.argsort(state.photon >= n_photons, stable=True)[: width // 4]
            state = jax.tree.map(lambda x, rows=order: x[rows], state)
    if shown:
        print(file=sys.stderr)
    records = np.concatenate(chunks)
    records = records[np.argsort(records[:, _PHOTON], kind="stable")]
    return WalkRecords(records[:, _RADIUS], records[:, _WEIGHT], records[:, _SIDE].astype(np.int32),
                       records[:, _PATH], records[:, _EXIT_COS], time.perf_counter() - start, steps)
