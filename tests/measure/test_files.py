"""A measurement from its files (measure.files): what read_measurement hands the fit, the
checks it makes with messages naming the file or the argument, and one fit end to end."""

import numpy as np
import pytest

from measure.checks import MeasurementError
from measure.exr import ExrError, write_exr
from measure.files import MeasurementImages, fit_images, read_measurement

RNG = np.random.default_rng(0)


def _beam(size=32, sigma_px=2.0, peak=1.0):
    rows, cols = np.indices((size, size)) - (size - 1) / 2
    return np.repeat((peak * np.exp(-(rows**2 + cols**2) / (2 * sigma_px**2)))[..., None], 3, -1)


def test_pixels_come_per_unit_exposure_with_the_dark_frame_off(tmp_path):
    """(frame - dark) / exposure for the measurement and the reference, each at its own
    exposure; the pixel size and channels from the measurement's header."""
    meas, ref, dark = 0.4 * _beam(sigma_px=4.0) + 0.01, _beam() + 0.01, np.full((32, 32, 3), 0.01)
    meas[0, 0] += RNG.uniform(0, 1e-3, 3)  # no plateau of equal maxima
    images = read_measurement(write_exr(tmp_path / "m.exr", meas, attributes={"jsss_pixel_mm": 0.05,
                                                                               "jsss_exposure": 2.0}),
                              write_exr(tmp_path / "r.exr", ref, attributes={"jsss_exposure": 0.5}),
                              dark=write_exr(tmp_path / "d.exr", dark))
    assert isinstance(images, MeasurementImages) and images.channels == ("R", "G", "B")
    assert images.pixel_mm == pytest.approx(0.05, rel=1e-7) and images.measurement_path.name == "m.exr"  # float32
    np.testing.assert_allclose(images.measurement, (meas.astype(np.float32) - 0.01) / 2.0, atol=1e-7)
    np.testing.assert_allclose(images.reference, (ref.astype(np.float32) - 0.01) / 0.5, atol=1e-7)


def test_problems_with_the_files_name_the_file(tmp_path):
    """A missing file, images of different shapes and a clipped reference: each error names
    the file at fault."""
    beam = write_exr(tmp_path / "m.exr", 0.4 * _beam(sigma_px=4.0))
    with pytest.raises(ExrError, match="nope.exr: no such file"):
        read_measurement(beam, tmp_path / "nope.exr")
    with pytest.raises(MeasurementError, match=r"small.exr: shape \(8, 8, 3\) differs from .*m.exr"):
        read_measurement(beam, write_exr(tmp_path / "small.exr", np.ones((8, 8, 3))))
    clipped = np.minimum(_beam(peak=4.0), 1.0)
    with pytest.raises(MeasurementError, match="clipped.exr: channel R looks saturated"):
        read_measurement(beam, write_exr(tmp_path / "clipped.exr", clipped))


def test_messages_name_the_argument_as_the_caller_spells_it(tmp_path):
    """Python's names by default; a command's options where it passes them (`names`)."""
    frames = [write_exr(tmp_path / f"t{i}.exr", _beam() * 0.5**i, attributes={"jsss_exposure": 0.5**i})
              for i in range(2)]
    ref = write_exr(tmp_path / "r.exr", _beam())
    with pytest.raises(MeasurementError, match=r"several measurement frames need saturation \(the clip level"):
        read_measurement(frames, ref)
    with pytest.raises(MeasurementError, match="several measurement frames need --saturation"):
        read_measurement(frames, ref, names={"saturation": "--saturation"})
    images = read_measurement(frames[0], ref)
    assert images.pixel_mm is None
    with pytest.raises(ValueError, match=r"t0.exr: no pixel size in the header \(jsss_pixel_mm\); pass pixel_mm"):
        fit_images(images, 1.3)
    with pytest.raises(ValueError, match=r"^eta must be > 0 .* got nan"):
        fit_images(images, float("nan"), pixel_mm=0.05)
    with pytest.raises(ValueError, match=r"^--eta must be > 0"):
        fit_images(images, -1.0, pixel_mm=0.05, names={"eta": "--eta"})
    with pytest.raises(ValueError, match=r"^reference_reflectance must be in \(0, 1\]"):
        fit_images(images, 1.3, pixel_mm=0.05, reference_reflectance=1.5)
    with pytest.raises(ValueError, match=r"^view_angle_deg must lie in \[0, 90\) degrees"):
        fit_images(images, 1.3, pixel_mm=0.05, view_angle_deg=90.0)
    with pytest.raises(ValueError, match=r"^model='transport': .*\(model='dipole' fits any eta"):
        fit_images(images, 1.3, pixel_mm=0.05, model="transport", g=0.3)
    with pytest.raises(ValueError, match=r"^--model transport: .*\(--model dipole fits any eta"):
        fit_images(images, 1.3, pixel_mm=0.05, model="transport", g=0.3, names={"model": "--model"})


def test_a_synthetic_measurement_fits_to_its_truth_and_a_swapped_one_names_both_files(tmp_path):
    """skin1 through its files (transport tables, noise, dark frame) within 5 % of the truth;
    the same files with measurement and reference swapped are refused, naming both."""
    from jsss.layers import hankel
    from jsss.materials import jensen2001
    from measure.synth import synthesize, write_measurement

    grid = hankel.hankel_grid()
    skin = jensen2001("skin1")
    paths = write_measurement(tmp_path, synthesize(skin, size=128, photons_per_unit=1e5, seed=0, grid=grid,
                                                   model="transport"), name="skin1")
    images = read_measurement(paths["measurement"], paths["reference"], dark=paths["dark"])
    fit = fit_images(images, 1.3, model="transport", grid=grid)
    table = fit.table()
    np.testing.assert_allclose(table["sigma_a"], np.asarray(skin.sigma_a), rtol=0.05)
    np.testing.assert_allclose(table["sigma_s_prime"], np.asarray(skin.sigma_s_prime), rtol=0.05)
    assert table["model"] == "transport" and table["quality"] == ["ok"] * 3
    swapped = read_measurement(paths["reference"], paths["measurement"], dark=paths["dark"])
    with pytest.raises(MeasurementError, match=r"skin1_ref.exr with reference .*skin1.exr: .*not a beam"):
        fit_images(swapped, 1.3, model="transport", grid=grid)
