"""Transport-exact profiles from the scaled Monte Carlo tables, against truths that do not share them:
independent walks with absorption in the walk, adding-doubling, energy conservation, finite
differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium, dipole, transport
from jsss.transport.montecarlo import _params, random_walk
from jsss.transport.photon_walk import run_walk
from jsss.transport.tables import TableGrid, tabulate
from tests.truth.adding_doubling import slab_rt

iadpython = pytest.importorskip("iadpython")

TABLE_PHOTONS = int(transport.table_info()["photons"])


def annulus_mean(fn, lo, hi, nodes=24):
    x, w = np.polynomial.legendre.leggauss(nodes)
    r = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
    values = np.asarray(fn(jnp.asarray(r)))
    return np.sum(w * 0.5 * (hi - lo) * 2 * np.pi * r * values) / (np.pi * (hi**2 - lo**2))


def table_total_error(eta, g, absorption_ratio):
    """Relative standard error of the tables' total at the nearest (eta, a') node."""
    info = transport.table_info()
    i = np.argmin(np.abs(info["etas"] - eta))
    j = np.argmin(np.abs(info["gs"] - g))
    k = np.argmin(np.abs(np.log(info["absorption"][1:]) - np.log(absorption_ratio))) + 1
    total = float(transport.total_reflectance(Medium(info["absorption"][k], 1.0, info["etas"][i]), g=g))
    return info["error_total"][i, j, k] / total


def table_error(share):
    """Relative standard error of a table cell that holds ``share`` of the photons (binomial)."""
    return np.sqrt((1 - share) / (share * TABLE_PHOTONS))


@pytest.mark.parametrize(
    "albedo, eta, g",
    [(0.5, 1.3, 0.0), (0.9, 1.0, 0.5), (0.99, 1.45, 0.8), (0.9, 1.25, 0.9)],
)
def test_profile_and_total_match_an_independent_walk(albedo, eta, g):
    """Annulus means of R(r) at 0.3-5 transport lengths and the total, against a walk that
    absorbs as it goes (its own seed), within 4 combined standard errors plus 1 % for the
    table's interpolation in eta (tested at off-node eta) and radius."""
    medium = Medium(1 - albedo, albedo, eta)
    radii = np.array([0.3, 1.0, 2.0, 5.0])
    edges = np.concatenate([[0.0], np.sort(np.concatenate([radii * 0.85, radii * 1.15])), [np.inf]])
    truth = random_walk(medium, g=g, n_photons=60_000, max_steps=2**31 - 1, bin_edges=edges, seed=101,
                        progress=False)
    for i in range(radii.size):
        k = 2 * i + 1
        lo, hi = edges[k], edges[k + 1]
        mc, err = truth.R_profile[k], truth.R_profile_err[k]
        if err > 0.05 * mc:
            continue
        model = annulus_mean(lambda r: transport.profile(medium, r, g=g), lo, hi)
        share = mc * np.pi * (hi**2 - lo**2) / 8  # the table's annuli are ~8 times narrower
        tolerance = 4 * np.hypot(err / mc, table_error(share)) + 0.01
        assert model / mc - 1 == pytest.approx(0.0, abs=tolerance), (lo, hi, model, mc, err)
    total = float(transport.total_reflectance(medium, g=g))
    assert total == pytest.approx(truth.R, abs=4 * truth.R_err + 0.002)


def test_high_albedo_total_and_profile_match_a_walk():
    """Albedo' 0.9999: paths of 10^4 transport lengths matter, beyond the tables' cap, so this
    checks the modelled tail. Total within 4 standard errors + 0.3 %."""
    medium = Medium(1e-4, 0.9999, 1.3)
    truth = random_walk(medium, n_photons=6000, max_steps=2**31 - 1, seed=5, progress=False)
    total = float(transport.total_reflectance(medium))
    assert truth.lost == 0.0
    assert total == pytest.approx(truth.R, abs=4 * truth.R_err + 0.003)


@pytest.mark.parametrize("albedo, g, eta", [(0.99, 0.0, 1.0), (0.95, 0.5, 1.4), (0.9, 0.9, 1.5)])
def test_total_matches_adding_doubling_within_half_a_percent(albedo, g, eta):
    """iadpython, a slab of 64 optical depths (semi-infinite at these albedos: the light
    reaching the bottom is below 1e-4 of the beam), converged in angle (64 quadrature points,
    96 at g = 0.9: tests/truth/adding_doubling.py). iadpython gives the
    collimated total with the specular reflection: UR1 = F(0) + (1 - F(0)) R_entering.
    Within 0.5 % plus three of the tables' own standard errors: at albedo' 0.47 (the g = 0.9
    case) 10^6 photons leave 0.45 % of noise on a total of 0.026."""
    UR1, UT1, _, _ = slab_rt(albedo, 64.0, g, eta)
    assert UT1 < 1e-4
    sigma_t = 1.0
    medium = Medium((1 - albedo) * sigma_t, albedo * sigma_t * (1 - g), eta)
    specular = float(1 - transport.entry_transmittance(eta))
    expected = (UR1 - specular) / (1 - specular)
    noise = table_total_error(eta, g, float(medium.sigma_a / medium.sigma_s_prime))
    assert float(transport.total_reflectance(medium, g=g)) == pytest.approx(expected, rel=0.005 + 3 * noise)


def _adding_doubling_total(reduced_albedo, eta, g):
    """iadpython (64 optical depths, converged in angle): the total per unit entering flux of a
    half space of this reduced albedo, and its medium (sigma_t 1)."""
    albedo = reduced_albedo / (1 - g + g * reduced_albedo)       # single-scattering albedo
    UR1, _, _, _ = slab_rt(albedo, 64.0, g, eta)
    specular = float(1 - transport.entry_transmittance(eta))
    return (UR1 - specular) / (1 - specular), Medium(1 - albedo, albedo * (1 - g), eta)


@pytest.mark.parametrize("g", [0.0, 0.5, 0.9])
@pytest.mark.parametrize("eta", [1.0, 1.3, 1.6])
@pytest.mark.parametrize("reduced_albedo", [0.0203, 0.067, 0.1])
def test_low_albedo_totals_are_within_half_a_percent_of_adding_doubling(reduced_albedo, eta, g):
    """Ketchup's green and blue (reduced albedo 0.067 and 0.020, issue 37) against adding-doubling
    converged in angle, which shares nothing with the walk. With the full walks' 2 x 10^6
    photons alone the totals at reduced albedo 0.02-0.2 were up to 3.3 % off at g = 0 and 2.2 %
    at g = 0.5 over eta 1.0-1.6: noise, one realisation of the few short paths that make a low
    albedo's light. The tables' early part (the paths up to 4 transport lengths, walked again:
    2 x 10^7 photons per (eta, g), first flights importance-sampled, and at g >= 0.5 the first
    three scatterings partly drawn over the whole sphere, since at g 0.9 a photon turns back
    once in 44) brings every eta 1.0-1.6 and reduced albedo 0.02-0.2 within 0.31 / 0.23 / 0.22 %
    at g 0 / 0.5 / 0.9 (0.35 % at g 0.8; 2026-12-06); here within 0.20 / 0.23 / 0.15 %."""
    expected, medium = _adding_doubling_total(reduced_albedo, eta, g)
    assert float(transport.total_reflectance(medium, g=g)) == pytest.approx(expected, rel=0.005)


@pytest.mark.parametrize("g", [0.0, 0.5, 0.8, 0.9])
def test_low_albedo_totals_scatter_as_their_stated_errors_say(g):
    """The totals are their stated noise, not a bias: over eta 1.0-1.6 (every node) and reduced
    albedo 0.02-0.2, z = (tables / adding-doubling - 1) / stated error has an RMS of 1.10 /
    0.93 / 1.49 / 0.82 and a mean of -0.02 / -0.07 / +0.03 / -0.37 at g 0 / 0.5 / 0.8 / 0.9
    (2026-12-06; stated errors 0.13-0.18 % at most). The z of one eta share its walk, about 7
    independent values, so the bounds are their 99 % interval: an RMS above 1.70 says the
    errors are understated (or a bias), below 0.38 overstated; a mean beyond +-1 (2.6 of its
    own spread) a bias."""
    z = []
    for eta in (1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6):
        for reduced_albedo in (0.0203, 0.05, 0.1, 0.2):
            expected, medium = _adding_doubling_total(reduced_albedo, eta, g)
            noise = table_total_error(eta, g, float(medium.sigma_a / medium.sigma_s_prime))
            z.append((float(transport.total_reflectance(medium, g=g)) / expected - 1) / noise)
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.38 < rms < 1.70, (rms, np.round(z, 2))
    assert abs(np.mean(z)) < 1.0


def test_non_absorbing_medium_returns_all_light():
    """sigma_a = 0: the total is 1 (the capped tail included), and the profile integrated over
    the plane out to 1000 transport lengths returns it to within its far tail (~r^-3)."""
    for eta in (1.0, 1.3, 1.6):
        medium = Medium(0.0, 2.0, eta)
        assert float(transport.total_reflectance(medium)) == pytest.approx(1.0, abs=1e-9)
        r = jnp.geomspace(1e-4, 500.0, 4000)
        integral = np.trapezoid(2 * np.pi * np.asarray(r) ** 2 * np.asarray(transport.profile(medium, r)),
                                np.log(np.asarray(r)))
        assert integral == pytest.approx(1.0, abs=0.02)


def test_scaling_maps_media_of_one_albedo_onto_each_other():
    """R(r; k sigma) = k^2 R(k r; sigma) for media of the same reduced albedo."""
    a = Medium(0.02, 1.0, 1.3)
    b = Medium(0.06, 3.0, 1.3)
    r = jnp.geomspace(0.01, 30.0, 50)
    np.testing.assert_allclose(np.asarray(transport.profile(b, r / 3)), 9 * np.asarray(transport.profile(a, r)),
                               rtol=1e-10)


def test_profile_is_smooth_and_approaches_the_dipole_far_away():
    """Far from the source diffusion is right: at 10-20 transport lengths and albedo' 0.999 the
    transport profile and the dipole agree within 10 % (the dipole's known asymptotic error is
    a few percent there); near the source they differ. Checked also: no kinks in log R."""
    medium = Medium(0.001, 0.999, 1.3)
    r = jnp.geomspace(10.0, 20.0, 5)
    np.testing.assert_allclose(np.asarray(transport.profile(medium, r)), np.asarray(dipole.profile(medium, r)),
                               rtol=0.1)
    fine = jnp.geomspace(0.05, 50.0, 400)
    log_r = np.log(np.asarray(fine))
    log_profile = np.log(np.asarray(transport.profile(medium, fine)))
    slope = np.diff(log_profile) / np.diff(log_r)
    assert np.max(np.abs(np.diff(slope))) < 0.3


def test_radiance_integrates_to_the_exitance_and_matches_a_walk():
    """2 pi int L(r, mu) mu dmu = R(r) (the tables' two outputs agree), and L at three exit
    angles against a walk with absorption that tallies exit cosines, within 4 standard errors
    + 3 % (the tables' 8 cosine bins are interpolated)."""
    medium = Medium(0.05, 0.95, 1.4)
    r = jnp.array([0.5, 1.0, 2.0])
    mu, w = np.polynomial.legendre.leggauss(64)
    mu, w = 0.5 * (mu + 1), 0.5 * w
    radiance = np.stack([np.asarray(transport.radiance(medium, r, m)) for m in mu], axis=-1)
    np.testing.assert_allclose(2 * np.pi * radiance @ (w * mu), np.asarray(transport.profile(medium, r)), rtol=0.03)

    params = _params([medium], [np.inf], g=0.0, eta_above=1 / 1.4, eta_below=1 / 1.4, relative=True)
    records = run_walk(params, n_photons=200_000, max_steps=2**31 - 1, seed=77, progress=False)
    left = records.side == 1
    for lo, hi in [(0.8, 1.25)]:
        ring = left & (records.radius >= lo) & (records.radius < hi)
        for mu_lo, mu_hi in [(0.2, 0.4), (0.5, 0.7), (0.85, 1.0)]:
            inside = ring & (records.exit_cos >= mu_lo) & (records.exit_cos < mu_hi)
            count = np.count_nonzero(inside)
            norm = records.radius.size * np.pi * (hi**2 - lo**2) * np.pi * (mu_hi**2 - mu_lo**2)
            truth = np.sum(records.weight[inside]) / norm
            err = truth / np.sqrt(count)
            x, wx = np.polynomial.legendre.leggauss(8)
            rr = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
            mm = 0.5 * (mu_hi - mu_lo) * x + 0.5 * (mu_hi + mu_lo)
            grid = np.asarray(transport.radiance(medium, jnp.asarray(rr)[:, None], jnp.asarray(mm)[None, :]))
            weights = np.outer(wx * 0.5 * (hi - lo) * 2 * rr, wx * 0.5 * (mu_hi - mu_lo) * 2 * mm)
            model = np.sum(grid * weights) / ((hi**2 - lo**2) * (mu_hi**2 - mu_lo**2))
            assert model == pytest.approx(truth, abs=4 * err + 0.03 * truth), (mu_lo, model, truth, err)


@pytest.mark.parametrize("sigma_a", [0.0, 0.01, 0.3])
def test_gradients_match_finite_differences(sigma_a):
    """d R(r) / d(sigma_a, sigma_s', eta) and dR/dr by central differences, at sigma_a = 0 too
    (one-sided there)."""
    def value(params, r):
        sa, ss, eta = params
        return transport.profile(Medium(sa, ss, eta), r, g=0.5)

    params = jnp.array([sigma_a, 1.3, 1.33])
    r = 0.7
    grad = np.asarray(jax.grad(lambda p: value(p, r))(params))
    assert np.all(np.isfinite(grad))
    for i in range(3):
        h = 1e-5
        up = params.at[i].add(h)
        down = params.at[i].add(-h) if not (i == 0 and sigma_a == 0.0) else params
        span = 2 * h if not (i == 0 and sigma_a == 0.0) else h
        fd = (float(value(up, r)) - float(value(down, r))) / span
        assert grad[i] == pytest.approx(fd, rel=2e-3, abs=1e-7)
    dr = float(jax.grad(lambda x: value(params, x))(r))
    fd = (float(value(params, r + 1e-5)) - float(value(params, r - 1e-5))) / 2e-5
    assert dr == pytest.approx(fd, rel=1e-3)


def test_works_under_jit_and_vmap_with_rgb_channels():
    medium = Medium(jnp.array([0.01, 0.05, 0.2]), jnp.array([1.0, 1.2, 1.5]), 1.4)
    r = jnp.geomspace(0.01, 10.0, 7)
    eager = transport.profile(medium, r)
    jitted = jax.jit(lambda m, r: transport.profile(m, r))(medium, r)
    assert eager.shape == (7, 3)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), rtol=1e-12)
    for c in range(3):
        one = Medium(medium.sigma_a[c], medium.sigma_s_prime[c], 1.4)
        np.testing.assert_allclose(np.asarray(transport.profile(one, r)), np.asarray(eager[:, c]), rtol=1e-12)


def test_bad_arguments_name_the_parameter():
    with pytest.raises(ValueError, match="g in"):
        transport.profile(Medium(0.1, 1.0, 1.3), 1.0, g=0.3)
    with pytest.raises(ValueError, match="eta 1.0-1.6"):
        transport.profile(Medium(0.1, 1.0, 1.8), 1.0)
    with pytest.raises(ValueError, match="sigma_s_prime > 0"):
        transport.total_reflectance(Medium(0.1, 0.0, 1.3))


def test_tabulation_of_a_small_walk_is_exact_per_photon():
    """The table at an absorption node equals the photon sum of exp(-a' L') it stands for."""
    params = _params([Medium(0.0, 1.0, 1.3)], [np.inf], g=0.0, eta_above=1 / 1.3, eta_below=1 / 1.3, relative=True)
    records = run_walk(params, n_photons=3000, max_steps=2**31 - 1, max_path=100.0, seed=3, progress=False)
    grid = TableGrid()
    left, lost = records.side == 1, records.side == 0
    table = tabulate(records.radius, records.path, records.exit_cos, left, lost, grid=grid, max_path=100.0)
    j = 10
    a = grid.absorption[j]
    direct = np.sum(np.exp(-a * records.path[left])) / records.radius.size
    tail = table["total"][j] - direct
    assert 0 <= tail <= np.mean(lost) * np.exp(-a * 100.0) + 1e-15
    assert table["total"][0] == pytest.approx(1.0, abs=1e-12)


def test_table_generation_is_reproducible_bit_for_bit():
    """scripts/generate_transport_tables.py builds the same arrays from the same seed (and
    different ones from another), whatever the lane count."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "generate_transport_tables.py"
    spec = importlib.util.spec_from_file_location("generate_transport_tables", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    kwargs = dict(photons=3000, max_path=50.0, progress=False)
    a = script.build([1.3], [0.5], seed=1, lanes=256, **kwargs)
    b = script.build([1.3], [0.5], seed=1, lanes=1024, **kwargs)
    c = script.build([1.3], [0.5], seed=2, lanes=256, **kwargs)
    assert np.array_equal(a["exitance"], b["exitance"]) and np.array_equal(a["total"], b["total"])
    assert not np.array_equal(a["exitance"], c["exitance"])
    # Seeds are averaged from the float32 tables, so averaging saved parts gives the same bits.
    import io

    def saved(table):
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **table)
        buffer.seek(0)
        return dict(np.load(buffer))

    direct, from_files = script.average([a, c]), script.average([saved(a), saved(c)])
    assert np.array_equal(direct["exitance"], from_files["exitance"])
    assert np.array_equal(direct["total"], from_files["total"]) and int(direct["photons"]) == 6000


@pytest.mark.parametrize("channel", [0, 1, 2])
def test_low_albedo_profile_keeps_its_light_near_the_source(channel):
    """Ketchup (reduced albedo 0.75 / 0.07 / 0.02): the profile integrated over the plane from
    r = 0 returns the total within 1 %, although a quarter of the blue light leaves within a
    thousandth of a transport length (the tables' inner disc); and the radiance integrated over
    the hemisphere is the exitance at 0.03-0.3 transport lengths too (a sparse cosine bin once
    made the radiance at r -> 0 grow without bound). Inside the inner disc the radiance is
    finite and joins the annuli continuously (a jump there once stalled fits); toward the normal
    it holds the beam's own single scattering (every collision on the beam's axis sends light
    along the normal to its entry point), a spike in angle that no interpolation between view
    directions 10 degrees apart integrates, so the hemisphere is not checked there. Measured
    (2026-12-06): within 3.6 % at 0.03-0.3; red reads -5.3 % at 0.01 and -7.3 % at 0.003
    transport lengths, the spike's edge."""
    from jsss.materials import jensen2001

    k = jensen2001("ketchup")
    medium = Medium(k.sigma_a[channel], k.sigma_s_prime[channel], 1.3)
    r = np.concatenate([[0.0], np.geomspace(1e-7, 300.0, 20000)])
    integral = np.trapezoid(2 * np.pi * r * np.asarray(transport.profile(medium, jnp.asarray(r))), r)
    assert integral == pytest.approx(float(transport.total_reflectance(medium)), rel=0.01)
    mu, w = np.polynomial.legendre.leggauss(64)
    mu, w = 0.5 * (mu + 1), 0.5 * w
    near = jnp.array([0.03, 0.1, 0.3]) / k.sigma_s_prime[channel]
    radiance = np.stack([np.asarray(transport.radiance(medium, near, m)) for m in mu], axis=-1)
    np.testing.assert_allclose(2 * np.pi * radiance @ (w * mu), np.asarray(transport.profile(medium, near)),
                               rtol=0.05)
    edge = 1e-3 / float(k.sigma_s_prime[channel])                # the disc's radius [mm]
    inner = np.asarray(transport.radiance(medium, jnp.array([1e-6, 0.5, 1 - 1e-6, 1 + 1e-6]) * edge, 1.0))
    assert np.all(np.isfinite(inner)) and np.all(inner > 0)
    assert inner[2] == pytest.approx(inner[3], rel=1e-4)


def test_interpolation_is_exact_for_straight_lines_up_to_the_end_nodes():
    """The spline in eta, a' and r reproduces a linear function on every interval, the two
    end intervals included (with the end node repeated it did not: the end tangent was
    halved, and the total at eta 1.55 read 0.9 % low at albedo' 0.5)."""
    from jsss.transport.profiles import _catmull_rom

    nodes = np.arange(7.0)
    position = jnp.linspace(0.0, 6.0, 121)
    index, weight = _catmull_rom(position, nodes.size)
    line = 3.0 * nodes - 2.0
    np.testing.assert_allclose((line[np.asarray(index)] * np.asarray(weight)).sum(-1), 3.0 * position - 2.0,
                               atol=1e-12)
    np.testing.assert_allclose(np.asarray(weight).sum(-1), 1.0, atol=1e-12)


@pytest.mark.parametrize("cos_exit", [None, 1.0, 0.7])
def test_fixed_slice_equals_the_full_interpolation_and_keeps_gradients(cos_exit):
    """A fit's slice (the tables interpolated in eta once) gives the same values as profile /
    radiance, at etas between table nodes, for exitance, a camera along the normal (one exit
    bin) and a tilted one (two bins mixed); its gradient in sigma_a is finite at sigma_a = 0."""
    medium = Medium(jnp.array([0.0, 0.05, 1.2]), jnp.array([1.0, 2.0, 0.07]), jnp.array([1.0, 1.33, 1.55]))
    r = np.geomspace(1e-4, 50.0, 200)
    fixed = transport.fixed_slice(medium.eta, g=0.8, cos_exit=cos_exit)
    full = (transport.profile(medium, r, g=0.8) if cos_exit is None
            else transport.radiance(medium, r, cos_exit, g=0.8))
    np.testing.assert_allclose(transport.slice_values(fixed, medium, r), full, rtol=1e-12, atol=1e-300)

    def at_one_radius(sigma_a):
        return jnp.sum(transport.slice_values(fixed, Medium(sigma_a, medium.sigma_s_prime, medium.eta), 0.3))

    gradient = jax.grad(at_one_radius)(medium.sigma_a)
    assert np.all(np.isfinite(gradient)) and np.all(np.asarray(gradient) < 0)  # absorption removes light
