"""Blurs: exact moments, the analytic Gaussian, chains equal direct blurs, stretch and wrap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss.render.blur import (_chain, uniform_stretch, blur_schedule, blur_step, hierarchical_blur, kernel,
                              spacing_for_variance)

S = 128


def delta(size=S, at=None):
    tex = np.zeros((size, size, 1))
    r, c = at or (size // 2, size // 2)
    tex[r, c, 0] = 1.0
    return tex


def moments(img, center=(S // 2, S // 2)):
    y, x = np.mgrid[: img.shape[0], : img.shape[1]]
    x, y = x - center[1], y - center[0]
    m = img.sum()
    return m, (img * x).sum() / m, (img * x**2).sum() / m, (img * y**2).sum() / m


def analytic(v, size=S):
    y, x = np.mgrid[:size, :size] - size // 2
    return np.exp(-(x**2 + y**2) / (2 * v)) / (2 * np.pi * v)


def test_dEon_kernel_is_the_seven_tap_gaussian():
    k, w = kernel(7)
    assert np.allclose(k, np.arange(-3, 4))
    assert np.allclose(w, np.exp(-k**2 / 2) / np.exp(-k**2 / 2).sum())


def test_spacing_gives_the_requested_variance_of_the_interpolated_kernel():
    rng = np.random.default_rng(0)
    k, w = kernel(7)
    for target in rng.uniform(0.01, 200.0, 20):
        s = float(spacing_for_variance(target, max_spacing=64))
        # Brute force: spread each tap over its two neighbouring texels and take the variance.
        x = k * s
        lo = np.floor(x)
        f = x - lo
        var = (w * ((1 - f) * lo**2 + f * (lo + 1) ** 2)).sum()
        assert var == pytest.approx(target, rel=1e-9)


@pytest.mark.parametrize("v", [0.3, 1.0, 4.0, 16.0, 50.0])
def test_one_step_keeps_mass_centre_and_variance_exactly(v):
    out = np.asarray(blur_step(jnp.asarray(delta()), np.ones((S, S)), (1.0, 1.0), v))[..., 0]
    mass, mean, vx, vy = moments(out)
    assert mass == pytest.approx(1.0, abs=1e-12)
    assert abs(mean) < 1e-12
    assert vx == pytest.approx(v, rel=1e-10) and vy == pytest.approx(v, rel=1e-10)


def test_delta_blurred_through_the_chain_is_the_analytic_gaussian():
    variances = np.array([1.0, 4.0, 16.0, 64.0])
    schedule = blur_schedule(variances, 1.0, max_ratio=2.0)
    out = np.asarray(hierarchical_blur(jnp.asarray(delta()), np.ones((S, S)), (1.0, 1.0), jnp.asarray(variances),
                                       schedule))
    errors = [np.abs(img[..., 0] - analytic(v)).max() / analytic(v).max() for v, img in zip(variances, out)]
    # Point samples of a Gaussian only 2 texels wide are not its discrete version (4 % at
    # v = 4 texel^2, the sampling error); it shrinks with width: measured 0.74 % at 16 and
    # 0.13 % at 64 texel^2.
    assert errors[1] < 0.06
    assert errors[2] < 0.01
    assert errors[3] < 0.003


def test_dEon_quadrupling_steps_alias_on_a_delta():
    """Why the planner halves the step growth for tight targets: 4x steps are 13-19 % off."""
    variances = np.array([64.0])
    errors = []
    for ratio in (4.0, 2.0):
        out = np.asarray(hierarchical_blur(jnp.asarray(delta()), np.ones((S, S)), (1.0, 1.0), jnp.asarray(variances),
                                           blur_schedule(variances, 1.0, max_ratio=ratio)))[0, ..., 0]
        errors.append(np.abs(out - analytic(64.0)).max() / analytic(64.0).max())
    assert errors[0] > 0.05 > 0.005 > errors[1]


def test_hierarchical_blurs_equal_direct_blurs_of_the_summed_variance():
    rng = np.random.default_rng(1)
    tex = jnp.asarray(rng.uniform(size=(S, S, 2)))
    mask = np.ones((S, S))
    chain = hierarchical_blur(tex, mask, (1.0, 1.0), jnp.asarray([3.0, 10.0, 30.0]),
                              blur_schedule([3.0, 10.0, 30.0], 1.0, max_ratio=2.0))
    direct = hierarchical_blur(tex, mask, (1.0, 1.0), jnp.asarray([30.0]), blur_schedule([30.0], 1.0, max_ratio=2.0))
    inner = (slice(20, -20), slice(20, -20))  # away from the border, where normalisation differs
    assert np.abs(np.asarray(chain[-1])[inner] - np.asarray(direct[0])[inner]).max() < 0.002


def test_stretch_makes_the_blur_isotropic_on_the_surface():
    """A texel 0.5 mm wide and 0.25 mm tall: the world variance is the same in both directions."""
    v = 4.0  # mm^2
    out = np.asarray(blur_step(jnp.asarray(delta()), np.ones((S, S)), (0.5, 0.25), v))[..., 0]
    _, _, vx, vy = moments(out)
    assert vx * 0.5**2 == pytest.approx(v, rel=1e-9)
    assert vy * 0.25**2 == pytest.approx(v, rel=1e-9)


def test_wrapped_u_keeps_light_that_crosses_the_seam():
    tex = delta(at=(S // 2, 1))
    mask = np.ones((S, S))
    wrapped = np.asarray(blur_step(jnp.asarray(tex), mask, (1.0, 1.0), 9.0, wrap_u=True))[..., 0]
    clamped = np.asarray(blur_step(jnp.asarray(tex), mask, (1.0, 1.0), 9.0, wrap_u=False))[..., 0]
    assert wrapped.sum() == pytest.approx(1.0, abs=1e-12)
    assert wrapped[:, -3:].sum() > 0.05 and clamped[:, -3:].sum() == 0


def test_masked_texels_neither_receive_nor_give_light():
    tex = np.ones((S, S, 1))
    mask = np.ones((S, S))
    mask[:, S // 2:] = 0
    tex[:, S // 2:] = 100.0  # garbage in the gutter
    out = np.asarray(blur_step(jnp.asarray(tex), mask, (1.0, 1.0), 25.0))[..., 0]
    assert np.allclose(out[:, : S // 2], 1.0)  # normalised: no darkening at the border
    assert np.all(out[:, S // 2:] == 0)


def test_schedule_rejects_unsorted_variances():
    with pytest.raises(ValueError, match="strictly increasing"):
        blur_schedule([4.0, 1.0], 1.0)


@pytest.mark.parametrize("wrap_u", [False, True])
def testuniform_stretch_slices_equal_the_per_texel_gathers_and_their_gradients(wrap_u):
    """One stretch for every texel (a plane) reads taps as shifted slices; a per-texel map of
    the same values reads them by gathers. Same blur, same derivative in the variance, at
    spacings below a texel, between texels and beyond the texture (variance 3000 texels^2)."""
    rng = np.random.default_rng(5)
    tex = jnp.asarray(rng.uniform(size=(S, S + 7, 2)))
    mask = (rng.uniform(size=(S, S + 7)) > 0.1).astype(float)  # holes: the normalisation matters
    pair = jnp.asarray([0.5, 0.25])
    per_texel = jnp.broadcast_to(pair, mask.shape + (2,))
    for v in (0.02, 1.7, 30.0, 190.0):
        sliced = blur_step(tex, mask, pair, v, wrap_u=wrap_u)
        gathered = blur_step(tex, mask, per_texel, v, wrap_u=wrap_u)
        assert np.abs(np.asarray(sliced) - np.asarray(gathered)).max() < 1e-12, v

        def loss(variance, stretch):
            return jnp.sum(blur_step(tex, mask, stretch, variance, wrap_u=wrap_u) * tex)

        d_sliced, d_gathered = jax.grad(loss)(v, pair), jax.grad(loss)(v, per_texel)
        assert np.isfinite(float(d_sliced)) and float(d_sliced) == pytest.approx(float(d_gathered), rel=1e-9, abs=1e-12)
    # The chain finds the uniform stretch itself, whatever invalid texels hold.
    holes = np.where(mask[..., None] > 0, np.asarray(per_texel), 0.0)
    schedule = blur_schedule([1.0, 8.0, 40.0], 0.5)
    chain = hierarchical_blur(tex, mask, holes, jnp.asarray([1.0, 8.0, 40.0]), schedule, wrap_u=wrap_u)
    gathered = _chain(tex, jnp.asarray(mask), jnp.asarray(holes), jnp.asarray([1.0, 8.0, 40.0]),
                      jnp.asarray(schedule.first_variance_ratio), substeps=schedule.substeps, taps=7, wrap_u=wrap_u)
    assert uniform_stretch(holes, mask).shape == (2,)
    isotropic = np.where(mask[..., None] > 0, 0.3, 0.0)  # one length per texel, (H, W, 1), as a plane's
    assert np.asarray(uniform_stretch(isotropic, mask)).tolist() == [0.3, 0.3]
    assert np.abs(np.asarray(chain) - np.asarray(gathered)).max() < 1e-12


def test_one_uniform_axis_reads_by_slices_and_equals_the_per_texel_map():
    """A sphere's v has one length on every texel (to rounding), its u does not: the chain then
    reads v's taps as slices and u's by gathers. Same blur and gradient as the full map."""
    rng = np.random.default_rng(7)
    tex = jnp.asarray(rng.uniform(size=(S, S + 5, 3)))
    mask = (rng.uniform(size=(S, S + 5)) > 0.1).astype(float)
    u = 0.2 + 0.3 * np.sin(np.linspace(0.1, 3.0, S))[:, None] * np.ones(S + 5)  # varies by row, like a sphere
    v = np.full(u.shape, 0.25) * (1 + 1e-15 * rng.standard_normal(u.shape))  # equal to rounding
    per_texel = np.stack([u, v], -1)
    axes = uniform_stretch(per_texel, mask)
    assert isinstance(axes, tuple) and axes[0].shape == u.shape and axes[1].shape == ()
    for variance in (0.05, 2.0, 40.0):
        mixed = blur_step(tex, mask, axes, variance, wrap_u=True)
        gathered = blur_step(tex, mask, jnp.asarray(per_texel), variance, wrap_u=True)
        assert np.abs(np.asarray(mixed) - np.asarray(gathered)).max() < 1e-12, variance

        def loss(var, stretch):
            return jnp.sum(blur_step(tex, mask, stretch, var, wrap_u=True) * tex)

        assert float(jax.grad(loss)(variance, axes)) == pytest.approx(
            float(jax.grad(loss)(variance, jnp.asarray(per_texel))), rel=1e-9)


@pytest.mark.parametrize("wrap_u", [False, True])
@pytest.mark.parametrize("uniform", [True, False])
def test_derivatives_in_the_texture_are_the_blur_itself(wrap_u, uniform):
    """A blur step is linear in the texture (the mask's weight does not depend on it), so its
    derivative along v is the step of v, and its transpose satisfies <J v, w> = <v, J^T w>.
    The pass's own derivative rule (the mask's channel left out) is checked against both, with
    holes in the mask, and against finite differences where the mask is differentiated too."""
    rng = np.random.default_rng(11)
    tex = jnp.asarray(rng.uniform(size=(40, 37, 3)))
    v, w = (jnp.asarray(rng.standard_normal((40, 37, 3))) for _ in range(2))
    mask = jnp.asarray((rng.uniform(size=(40, 37)) > 0.2).astype(float))
    stretch = jnp.asarray([0.5, 0.25]) if uniform else jnp.asarray(0.25 + 0.2 * rng.uniform(size=(40, 37, 2)))
    for variance in (0.03, 2.0, 40.0):
        def step(t, m=mask, variance=variance):
            return blur_step(t, m, stretch, variance, wrap_u=wrap_u)

        _, jv = jax.jvp(step, (tex,), (v,))
        assert np.abs(np.asarray(jv) - np.asarray(step(v))).max() < 1e-12
        _, pull = jax.vjp(step, tex)
        jtw = pull(w)[0]
        assert float(jnp.sum(jv * w)) == pytest.approx(float(jnp.sum(v * jtw)), rel=1e-12)
        # the mask differentiated too (its own path): central differences of a smooth mask
        smooth = mask * 0.5 + 0.25
        dm = jnp.asarray(rng.standard_normal(mask.shape))
        _, both = jax.jvp(step, (tex, smooth), (v, dm))
        h = 1e-6
        fd = (step(tex + h * v, smooth + h * dm) - step(tex - h * v, smooth - h * dm)) / (2 * h)
        assert np.abs(np.asarray(both) - np.asarray(fd)).max() < 1e-7 * max(1.0, float(jnp.abs(fd).max()))


def test_the_derivative_in_the_variance_matches_finite_differences():
    """Where the spacing has a tangent (a variance differentiated), the pass is differentiated
    itself, not by the texture-only rule: against central differences, at variances whose
    spacings lie between the table's breakpoints (there the blur is smooth in the variance)."""
    rng = np.random.default_rng(13)
    tex = jnp.asarray(rng.uniform(size=(32, 29, 3)))
    mask = jnp.asarray((rng.uniform(size=(32, 29)) > 0.2).astype(float))
    for stretch in (jnp.asarray([0.5, 0.25]), jnp.asarray(0.25 + 0.2 * rng.uniform(size=(32, 29, 2)))):
        for variance in (0.7, 9.3):
            def step(v, stretch=stretch):
                return blur_step(tex, mask, stretch, v)

            _, d = jax.jvp(step, (variance,), (1.0,))
            h = 1e-6 * variance
            fd = (step(variance + h) - step(variance - h)) / (2 * h)
            assert np.abs(np.asarray(d) - np.asarray(fd)).max() < 1e-6 * max(1.0, float(jnp.abs(fd).max()))
