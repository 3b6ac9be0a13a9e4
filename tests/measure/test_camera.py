"""What a camera records: radiance toward it, fitted against images whose truth is a random walk.

The images come from :mod:`measure.synth_transport` (a walk that shares no code with the
tables the transport model interpolates, own seeds). Their camera looks from exactly 0 degrees
(next-event estimates), as a real one does; the tables' radiance is toward that exact direction
too (issue 37: before, they held the 0-20.7 degree average, and these images were made to match).
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from jsss import Medium, dipole, hankel
from jsss.fresnel import exit_lobe
from fitting.medium import fit_medium
from measure.exr import write_exr
from measure.pipeline import fit_measurement
from measure.profile import beam_center, radial_profile
from measure.synth_transport import synthesize_walk

@pytest.fixture(scope="module")
def grid():
    return hankel.hankel_grid()


@pytest.fixture(scope="module")
def walk_image():
    """Albedo 0.99, eta 1.3, g 0, transport length 1 mm, 10^6 photons (about 20 s)."""
    medium = Medium(0.01, 0.99, 1.3)
    return medium, synthesize_walk(medium, photons=1_000_000, size=128, pixel_mm=0.05, seed=3)


def _fit(image, medium, grid, **kwargs):
    fit = fit_measurement(image.measurement, image.reference, 0.05, float(medium.eta), channels=("Y",), grid=grid,
                          **kwargs)
    return fit.table()


def _errors(table, medium):
    """(relative error, z) of sigma_a and sigma_s'."""
    out = []
    for key, true in (("sigma_a", float(medium.sigma_a)), ("sigma_s_prime", float(medium.sigma_s_prime))):
        value, err = table[key][0], table[f"{key}_err"][0]
        out.append((value / true - 1, (value - true) / err))
    return out


def test_transport_camera_fit_recovers_a_walks_medium(walk_image, grid):
    """The transport model's radiance, calibrated like a camera image (pi (1 - F(0)) L), recovers
    both coefficients within 3 of their stated standard errors, which must be informative
    (below 10 % for sigma_a, 2 % for sigma_s'; measured on this seed, exact-direction image and
    tables, 2026-12-06: sigma_a +5.8 % (z 2.3, stated 2.5 %), sigma_s' +0.1 % (z 0.4), chi^2/dof
    2.9; with the cone camera and cone tables it was +12.3 % (z 1.5), +0.7 % (z 0.6) at 1.2), and
    the fit's quality is ok."""
    medium, image = walk_image
    table = _fit(image, medium, grid, model="transport", view_angle_deg=0.0)
    for (rel, z), limit in zip(_errors(table, medium), (0.10, 0.02)):
        assert abs(z) < 3 and abs(rel / z) < limit, (rel, z)
    assert table["quality"] == ["ok"] and table["converged"] == [True]
    assert table["observable"] == "radiance"


def test_reading_a_camera_image_as_exitance_is_biased_and_flagged(walk_image, grid):
    """The same image fitted as exitance, or with the dipole's radiance law: worse by far
    (measured on this seed, 2026-12-06, as exitance: sigma_a -99.9 %, sigma_s' -22 %, chi^2/dof
    2.6e3; dipole: sigma_a -28 %, sigma_s' -20 %, chi^2/dof 7.1e3; with the cone camera the
    exitance read was -30 % / -7 % at 16)."""
    medium, image = walk_image
    exact = max(abs(z) for _, z in _errors(_fit(image, medium, grid, model="transport"), medium))
    for kwargs in (dict(model="transport", view_angle_deg=None), dict(model="dipole", view_angle_deg=0.0)):
        table = _fit(image, medium, grid, **kwargs)
        worst = max(abs(rel) for rel, _ in _errors(table, medium))
        assert worst > 0.1 and max(abs(z) for _, z in _errors(table, medium)) > exact, kwargs
    assert _fit(image, medium, grid, model="dipole")["quality"][0].startswith("poor")


@pytest.fixture(scope="module")
def wide_walk_image():
    """Albedo' 0.99, eta 1.3, g 0: 5 x 10^5 photons on 256 px of 0.18 mm, a half-field of 4
    diffusion lengths (1/sigma_tr = 5.8 mm), the framing benchmarks/measurement_transport.py uses."""
    medium = Medium(0.01, 0.99, 1.3)
    pixel_mm = 4 / np.sqrt(3 * 0.01) / 128
    return medium, pixel_mm, synthesize_walk(medium, photons=500_000, size=256, pixel_mm=pixel_mm,
                                             beam_sigma_mm=pixel_mm, seed=5)


@pytest.mark.xfail(strict=False, reason="known defect (2026-12-06): at albedo' 0.99, eta 1.3, g 0 toward the normal "
                   "sigma_a comes out +1.0 / +1.4 / +0.9 / +2.0 / +1.8 % at z 1.8 / 2.7 / 1.8 / 3.3 / 3.3 and sigma_s' "
                   "-0.3 to -0.7 % at z -1.5 to -2.9 (seeds 5-9) against stated errors of 0.5 and 0.2 %: a lean "
                   "the stated errors do not hold (+1.6 to +2.1 % at z 3.2-4.1 before the late light's slope in mu "
                   "became per radius)")
def test_a_field_of_four_diffusion_lengths_measures_sigma_a_within_3_percent(wide_walk_image, grid):
    """Framed to reach the profile's decay, the camera fit of a walk at albedo' 0.99 gets both
    coefficients within 3 % and within 3 stated errors, and the stated errors are small (the
    narrow field of `walk_image`, 0.55 diffusion lengths, states 8 % for sigma_a with twice
    the photons). No field warning. Measured with exact-direction images (2026-12-06): sigma_a
    +1.0 % (z 1.8), sigma_s' -0.7 % (z -2.9) on this seed, within 3 % and (barely) within 3
    stated errors; two of five seeds are not (xfail)."""
    medium, pixel_mm, image = wide_walk_image
    fit = fit_measurement(image.measurement, image.reference, pixel_mm, 1.3, channels=("Y",), grid=grid,
                          model="transport")
    table = fit.table()
    for rel, z in _errors(table, medium):
        assert abs(rel) < 0.03 and abs(z) < 3, (rel, z)
    assert table["sigma_a_err"][0] / 0.01 < 0.025 and table["sigma_s_prime_err"][0] / 0.99 < 0.02
    assert table["field_diffusion_lengths"][0] == pytest.approx(4.0, rel=0.1)
    assert fit.warnings == [] and table["quality"] == ["ok"]


def test_a_field_short_of_the_diffusion_length_is_named_as_the_cause(wide_walk_image, grid):
    """The centre 12 x 12 pixels of the same image (0.16 diffusion lengths): sigma_a's stated
    error grows past 10 % (measured 71 % of the truth; 0.54 % on the full field), and the fit says the field,
    not the fit, is the cause, with the diffusion length and the fix; the estimate stays within
    3 of its (now wide) stated errors. (With exact-direction images, smoother than a cone
    camera's, the centre 24 x 24 pixels, 0.37 diffusion lengths, already state 6.5 %: tight
    enough that no warning is due.)"""
    medium, pixel_mm, image = wide_walk_image
    lo, hi = 128 - 6, 128 + 6
    fit = fit_measurement(image.measurement[lo:hi, lo:hi], image.reference[lo:hi, lo:hi], pixel_mm, 1.3,
                          channels=("Y",), grid=grid, model="transport")
    table = fit.table()
    assert table["field_diffusion_lengths"][0] < 0.5
    assert table["sigma_a_err"][0] / 0.01 > 0.1 and abs(_errors(table, medium)[0][1]) < 3
    (message,) = fit.warnings
    assert "channel Y" in message and "diffusion lengths" in message and "widen the field" in message


def test_a_slanted_camera_fits_past_the_beams_single_scattering_streak(grid):
    """A camera at 40 degrees sees the beam's single scattering as a streak one beam wide along
    its azimuth; near the beam a ring of pixels hits or misses it, so its mean is not the
    azimuthal average the model is. Skin1's red (albedo' 0.96) on an independent walk's image:
    with bins from 2 pixels (the default before 2026-12-06) the rings near the beam read -43 to
    +79 % and the fit's chi^2/dof is 23.6 (sigma_s' -3.3 %, inside its inflated error); the
    default now starts past three of the streak's decay lengths (from a first fit: 9.2 pixels)
    and gets both coefficients within 3 % and 3 stated errors at chi^2/dof below 2 (measured:
    sigma_a +0.6 %, z 0.8; sigma_s' +0.3 %, z 0.4; chi^2/dof 0.41)."""
    from measure.pipeline import _streak_length_mm

    medium = Medium(0.032, 0.74, 1.3)
    pixel_mm = 4 / np.sqrt(3 * 0.032 * 0.772) / 128
    image = synthesize_walk(medium, photons=300_000, size=256, pixel_mm=pixel_mm, beam_sigma_mm=pixel_mm,
                            view_deg=40.0, seed=21)
    result = fit_measurement(image.measurement, image.reference, pixel_mm, 1.3, channels=("Y",), grid=grid,
                             view_angle_deg=40.0)
    table = result.table()
    for rel, z in _errors(table, medium):
        assert abs(rel) < 0.03 and abs(z) < 3, (rel, z)
    assert table["chi2_reduced"][0] < 2 and table["quality"] == ["ok"]
    assert result.r_min_mm == pytest.approx(3 * float(_streak_length_mm(result.fit.medium, 40.0, 0.0)[0]), rel=0.05)
    assert result.r_min_mm > 6 * pixel_mm
    near = fit_measurement(image.measurement, image.reference, pixel_mm, 1.3, channels=("Y",), grid=grid,
                           view_angle_deg=40.0, r_min_mm=2 * pixel_mm).table()
    assert near["chi2_reduced"][0] > 4


def test_far_bins_that_no_photon_reached_do_not_steer_the_fit(grid):
    """Skin1's blue (albedo' 0.68) at g 0.9 seen at 40 degrees, framed as for its red (0.115 mm
    pixels, a half-field of 14.7 mm; blue's light is gone within 4 mm). The far bins hold a few
    deep photons or none: means of 1e-48 to 1e-13 where the walk's expectation is 1e-9. Each
    bin's own scatter called them known to 1e-27, and before 2026-12-06 the fit ran every
    estimate to a profile of zero (this seed: sigma_s' 1.8e22 / mm, chi^2/dof 39; six seeds
    of three channels' walk: +35 to +100 % or ran off). A bin's noise now comes from at least
    one hit's worth of signal, then from the fit's expectation: both coefficients within 3 %
    and 3 stated errors (seeds 21-26: within 2.5 %, |z| < 0.6)."""
    medium = Medium(0.48, 1.01, 1.3)
    pixel_mm = 4 / np.sqrt(3 * 0.032 * 0.772) / 128
    image = synthesize_walk(medium, g=0.9, photons=300_000, size=256, pixel_mm=pixel_mm, beam_sigma_mm=pixel_mm,
                            view_deg=40.0, seed=23)
    own_scatter = radial_profile(image.measurement, beam_center(image.reference), pixel_mm, n_bins=48)
    assert np.min(own_scatter.stderr[own_scatter.stderr > 0]) < 1e-20  # the hard case is in this image
    result = fit_measurement(image.measurement, image.reference, pixel_mm, 1.3, channels=("Y",), grid=grid, g=0.9,
                             view_angle_deg=40.0)
    table = result.table()
    for rel, z in _errors(table, medium):
        assert abs(rel) < 0.03 and abs(z) < 3, (rel, z)
    assert table["quality"] == ["ok"] and table["converged"] == [True]


def test_exit_lobe_carries_the_exitance_and_the_dipole_radiance_uses_it():
    """int L cos dw over the outside hemisphere is the exitance (quadrature, eta 1.0-1.6), and
    dipole.radiance is the profile times that lobe."""
    mu = np.linspace(0, 1, 20001)
    for eta in (1.0, 1.3, 1.6):
        lobe = np.asarray(exit_lobe(mu, eta))
        assert np.trapezoid(lobe * mu * 2 * np.pi, mu) == pytest.approx(1.0, rel=1e-6)
    medium = Medium(0.01, 1.0, 1.4)
    r = np.array([0.3, 1.0, 3.0])
    np.testing.assert_allclose(dipole.radiance(medium, r, 0.8), dipole.profile(medium, r) * exit_lobe(0.8, 1.4),
                               rtol=1e-12)


def test_view_cos_is_checked(grid):
    profile = np.ones((3, 1))
    with pytest.raises(ValueError, match=r"view_cos=...\) must lie in \(0, 1\]"):
        fit_medium(profile, profile * 0.01, 1.3, pixel_radii=np.array([0.5, 1.0, 2.0]), bin_index=np.array([0, 1, 2]),
                   view_cos=0.0, grid=grid)


def test_command_line_view_angle_and_exitance(walk_image, tmp_path):
    """--view-angle is validated; --exitance is recorded as the observable in the JSON. A camera
    image at exactly 0 degrees read as exitance is not a measurement (measured chi^2/dof 2.6e3:
    the radiance toward the normal near the beam holds the beam's own single scattering, which
    exitance spreads over every direction), so the command exits 1 unless --accept-poor."""
    _, image = walk_image
    meas = write_exr(tmp_path / "m.exr", image.measurement, ("Y",), attributes={"jsss_pixel_mm": 0.05})
    ref = write_exr(tmp_path / "r.exr", image.reference, ("Y",), attributes={"jsss_pixel_mm": 0.05})

    def run(*args):
        return subprocess.run([sys.executable, "-m", "measure.commands.fit_params", str(meas), "--reference", str(ref),
                               "--eta", "1.3", *args], capture_output=True, text=True, stdin=subprocess.DEVNULL,
                              timeout=600)

    bad = run("--view-angle", "nan")
    assert bad.returncode == 2 and "--view-angle must lie in [0, 90) degrees" in bad.stderr
    refused = run("--exitance", "--model", "transport", "--json")
    assert refused.returncode == 1 and "not a measurement" in refused.stderr, refused.stderr
    out = run("--exitance", "--model", "transport", "--json", "--accept-poor")
    assert out.returncode == 0, out.stderr
    table = json.loads(out.stdout)
    assert table["observable"] == "exitance" and table["view_angle_deg"] is None


def test_dipole_warns_where_its_bias_exceeds_its_stated_error(walk_image, tmp_path):
    """--model dipole on a transport-truth image: the transport refit differs by more than a stated
    error, so that coefficient gets a warning naming diffusion's bias; the JSON records the
    relative differences (measured 2026-12-06 on the exact-direction image: dipole sigma_s' -20 %,
    sigma_a -28 % against transport's +0.2 % / +6.1 %; with the cone camera sigma_s' -15 %, and
    sigma_a +200 % while the fit weighted log residuals). Its chi2/dof (7.1e3 measured) is past
    what a measurement can be: the estimate is kept apart and the command exits 1."""
    _, image = walk_image
    meas = write_exr(tmp_path / "m.exr", image.measurement, ("Y",), attributes={"jsss_pixel_mm": 0.05})
    ref = write_exr(tmp_path / "r.exr", image.reference, ("Y",), attributes={"jsss_pixel_mm": 0.05})
    out = subprocess.run([sys.executable, "-m", "measure.commands.fit_params", str(meas), "--reference", str(ref),
                          "--eta", "1.3", "--model", "dipole", "--json"], capture_output=True, text=True,
                         stdin=subprocess.DEVNULL, timeout=600)
    assert out.returncode == 1, out.stderr
    table = json.loads(out.stdout)
    assert table["status"] == ["poor"] and table["sigma_a"] == [None] and table["estimate"]["sigma_a"][0] > 0
    assert table["dipole_minus_transport"]["sigma_s_prime"][0] < -0.1
    assert "diffusion's bias, not noise" in out.stderr


def test_transport_synthesis_refuses_media_the_tables_do_not_cover(grid):
    # The synthesis evaluates the tables under jit, where their own checks cannot see values:
    # it checks first, naming the value.
    from measure.synth import synthesize

    for medium, g, named in ((Medium(0.01, 1.0, 1.8), 0.0, "eta"), (Medium(0.01, 1.0, 1.3), 0.3, "g"),
                             (Medium(5.0, 0.001, 1.3), 0.0, "sigma_a / sigma_s_prime")):
        with pytest.raises(ValueError, match=named):
            synthesize(medium, size=32, model="transport", g=g, grid=grid)


def test_an_image_less_noisy_than_the_tables_is_not_called_poor(grid):
    """Skin1's red (albedo' 0.96, eta 1.3) from 4.8e6 walk photons: the image's noise is below the
    transport tables' own, whose shape the model carries and no parameter removes. Against the
    data's noise alone chi^2/dof reads 8.5, which had called the fit poor (above 4) with both
    coefficients within 1.2 %; with the tables' noise in the residuals' covariance it reads 1.1
    (measured 2026-12-06), the quality is ok, and the estimates stand (within 3 %)."""
    from jsss.materials import material

    skin = material("skin1")
    medium = Medium(float(np.asarray(skin.sigma_a)[0]), float(np.asarray(skin.sigma_s_prime)[0]), 1.3)
    pixel_mm = 4 / np.sqrt(3 * float(medium.sigma_a) * float(medium.sigma_a + medium.sigma_s_prime)) / 128
    image = synthesize_walk(medium, photons=4_800_000, size=256, pixel_mm=pixel_mm, beam_sigma_mm=pixel_mm, seed=21)
    table = fit_measurement(image.measurement, image.reference, pixel_mm, 1.3, channels=("Y",), grid=grid).table()
    assert table["chi2_reduced"][0] > 4  # the hard case is in the image
    assert table["chi2_reduced_tables"][0] < 2 and table["quality"] == ["ok"]
    for rel, _ in _errors(table, medium):
        assert abs(rel) < 0.03, rel
