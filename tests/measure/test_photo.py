"""Camera photos in: raw (a DNG written here, read by LibRaw through rawpy) and 16-bit TIFF/PNG.

The files are made by the tests from known linear images, so every value read back has an
answer; the end-to-end tests fit synthetic measurements written as raw brackets and as TIFFs.
"""

import json
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest

from jsss.materials import jensen2001
from measure.photo import NonLinearWarning, PhotoError, read_image
from measure.synth import synthesize
from tests.helpers import png16

BLACK, WHITE = 512, 16383


def write_dng(path, rgb, exposure_s=None, *, black=BLACK, white=WHITE):
    """A minimal DNG: an RGGB Bayer mosaic of ``rgb`` (linear, 1.0 = the white level)."""
    import tifffile

    v = np.clip(np.asarray(rgb, float), 0.0, 1.0)
    cfa = np.empty(v.shape[:2])
    cfa[0::2, 0::2], cfa[0::2, 1::2] = v[0::2, 0::2, 0], v[0::2, 1::2, 1]
    cfa[1::2, 0::2], cfa[1::2, 1::2] = v[1::2, 0::2, 1], v[1::2, 1::2, 2]
    data = np.round(black + cfa * (white - black)).astype(np.uint16)
    identity = (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
    tags = [(50706, "B", 4, (1, 4, 0, 0), True), (50708, "s", 0, "jsss test camera", True),
            (33421, "H", 2, (2, 2), True), (33422, "B", 4, (0, 1, 1, 2), True), (50710, "B", 3, (0, 1, 2), True),
            (50714, "H", 1, (black,), True), (50717, "H", 1, (white,), True), (50721, "2i", 9, identity, True),
            (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True)]
    if exposure_s is not None:
        f = Fraction(exposure_s).limit_denominator(10**6)
        tags.append((33434, "2I", 1, (f.numerator, f.denominator), True))
    tifffile.imwrite(path, data, photometric=32803, extratags=tags, subfiletype=0, metadata=None)
    return path


def write_tiff(path, rgb, *, exposure_s=None, iso=None, bits=16, srgb=False):
    import tifffile

    scale = 2**bits - 1
    data = np.round(np.clip(rgb, 0, 1) * scale).astype(np.uint16 if bits == 16 else np.uint8)
    tags = []
    if exposure_s is not None:
        f = Fraction(exposure_s).limit_denominator(10**6)
        tags.append((33434, "2I", 1, (f.numerator, f.denominator), True))
    if iso is not None:
        tags.append((34855, "H", 1, (iso,), True))
    if srgb:
        tags.append((34675, "B", 16, b"....sRGB profile", True))
    tifffile.imwrite(path, data, photometric="rgb", extratags=tags, metadata=None)
    return path


def _gradient(h=32, w=48):
    rows, cols = np.indices((h, w))
    return np.stack([0.1 + 0.6 * cols / w, np.full((h, w), 0.3), 0.05 + 0.4 * rows / h], axis=-1)


def test_dng_reads_back_linear_with_black_level_off_and_exposure(tmp_path):
    """LibRaw demosaics bilinearly: on a linear gradient that is exact to the 14-bit step away
    from the border; the exposure time comes from the file, the clip level is 1."""
    truth = _gradient()
    image = read_image(write_dng(tmp_path / "g.dng", truth, exposure_s=0.01))
    assert image.channels == ("R", "G", "B") and image.header["jsss_exposure"] == pytest.approx(0.01)
    assert image.header["jsss_saturation"] == 1.0 and image.header["jsss_white_balance"] == "none"
    np.testing.assert_allclose(image.pixels[2:-2, 2:-2], truth[2:-2, 2:-2], atol=2.0 / (WHITE - BLACK))


def test_dng_clipped_sensor_pixels_are_marked_at_the_clip_level(tmp_path):
    truth = _gradient()
    truth[10, 20] = 1.5  # one sensor pixel beyond the white level
    truth[0, 0] = 1.5  # and one in a corner: its mark must not wrap to the opposite edges
    image = read_image(write_dng(tmp_path / "c.dng", truth))
    assert np.all(image.pixels[9:12, 19:22] == 1.0) and np.all(image.pixels[20:, :] < 1.0)
    assert np.all(image.pixels[:2, :2] == 1.0)
    assert np.all(image.pixels[-1, :] < 1.0) and np.all(image.pixels[:, -1] < 1.0)


def test_tiff_scales_integers_and_reads_exposure_and_iso(tmp_path):
    truth = _gradient()
    image = read_image(write_tiff(tmp_path / "t.tif", truth, exposure_s=0.02, iso=400))
    np.testing.assert_allclose(image.pixels, truth, atol=0.5 / 65535)
    assert image.header["jsss_exposure"] == pytest.approx(0.02 * 4)


def test_tiff_that_says_srgb_warns_and_8_bit_is_refused(tmp_path):
    with pytest.warns(NonLinearWarning, match="sRGB"):
        read_image(write_tiff(tmp_path / "s.tif", _gradient(), srgb=True))
    with pytest.raises(PhotoError, match="8-bit image"):
        read_image(write_tiff(tmp_path / "b.tif", _gradient(), bits=8))


def test_png_16_bit_reads_linear(tmp_path):
    import imageio.v3 as iio

    grey = np.round(_gradient()[..., 0] * 65535).astype(np.uint16)
    iio.imwrite(tmp_path / "p.png", grey)
    image = read_image(tmp_path / "p.png")
    np.testing.assert_allclose(image.pixels[..., 1], grey / 65535.0)


@pytest.mark.parametrize("name, content, expected", [
    ("x.dng", b"not a raw file", "not a readable raw file"),
    ("x.tif", b"not a tiff", "not a readable TIFF file"),
    ("x.png", b"not a png", "not a readable PNG file"),
    ("x.jpg", b"", "unsupported image type .jpg"),
])
def test_corrupt_or_unsupported_files_give_one_line_errors(tmp_path, name, content, expected):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(PhotoError, match=expected) as info:
        read_image(tmp_path / name)
    assert str(tmp_path / name) in str(info.value) and "\n" not in str(info.value)


def _fit(*args):
    out = subprocess.run([sys.executable, "-m", "measure.commands.fit_params", *map(str, args)], capture_output=True,
                         text=True, timeout=600, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_raw_brackets_and_reference_fit_end_to_end(tmp_path):
    """Three clipped raw brackets of marble (14-bit DNGs, exposure from the files, clip level
    from LibRaw) and a raw reference at its own exposure fit within 5 % of the truth."""
    marble = jensen2001("marble")
    kwargs = dict(size=128, pixel_mm=0.05, beam_sigma_mm=0.15, model="transport", seed=3)
    peak = synthesize(marble, noise=False, **kwargs).measurement.max()
    clip = 1.0
    exposures = [0.5 * clip / peak * f for f in (1.0, 16.0, 256.0)]
    # 40 000 electrons at the clip level, a typical full well
    s = synthesize(marble, photons_per_unit=4e4 / clip, exposures=exposures, saturation=clip, **kwargs)
    frames = [write_dng(tmp_path / f"m_t{i}.dng", frame / clip, exposure_s=t) for i, (frame, t) in enumerate(s.frames)]
    t_ref = 0.5 * clip / s.reference.max()
    reference = write_dng(tmp_path / "m_ref.dng", s.reference * t_ref / clip, exposure_s=t_ref)
    table = _fit(*frames, "--reference", reference, "--pixel-mm", 0.05, "--eta", 1.5, "--json")
    np.testing.assert_allclose(table["sigma_a"], np.asarray(marble.sigma_a), rtol=0.05)
    np.testing.assert_allclose(table["sigma_s_prime"], np.asarray(marble.sigma_s_prime), rtol=0.05)


def test_tiff_measurement_and_reference_at_different_exposures_fit_end_to_end(tmp_path):
    """16-bit TIFFs exposed differently (time and ISO in the metadata) calibrate per unit
    exposure: skin1 within 5 % of the truth."""
    skin = jensen2001("skin1")
    s = synthesize(skin, size=128, pixel_mm=0.05, beam_sigma_mm=0.1, photons_per_unit=1e6, model="transport", seed=4)
    t_meas, t_ref = 0.9 / s.measurement.max() / 2, 0.9 / s.reference.max()  # the measurement at ISO 200
    meas = write_tiff(tmp_path / "s.tif", s.measurement * t_meas * 2, exposure_s=t_meas, iso=200)
    ref = write_tiff(tmp_path / "s_ref.tif", s.reference * t_ref, exposure_s=t_ref, iso=100)
    table = _fit(meas, "--reference", ref, "--pixel-mm", 0.05, "--eta", 1.3, "--json")
    np.testing.assert_allclose(table["sigma_a"], np.asarray(skin.sigma_a), rtol=0.05)
    np.testing.assert_allclose(table["sigma_s_prime"], np.asarray(skin.sigma_s_prime), rtol=0.05)


@pytest.mark.parametrize("planes", [3, 4])
def test_a_16_bit_colour_png_reads_every_sample_exactly(tmp_path, planes):
    """Pillow cuts 16-bit colour samples to 8 bits (a valid file had been refused as "8-bit").
    RGB and RGBA, every filter type: each sample reads back as its code / 65535, alpha dropped."""
    pixels = (np.random.default_rng(0).random((11, 7, planes)) * 65535).astype(np.uint16)
    image = read_image(png16(tmp_path / f"rgb16_{planes}.png", pixels))
    np.testing.assert_array_equal(image.pixels, pixels[..., :3] / 65535.0)


def test_a_png_header_larger_than_memory_is_refused_before_decoding(tmp_path):
    """A 100000^2 16-bit RGB PNG header over a few bytes of data: one line naming the file and the
    memory, before any decoder allocates (pypng and Pillow would both try)."""
    import struct

    header = struct.pack(">IIBBBBB", 100_000, 100_000, 16, 2, 0, 0, 0)
    path = png16(tmp_path / "huge.png", np.zeros((1, 1, 3), np.uint16), header=header)
    with pytest.raises(PhotoError, match=r"huge\.png: its header's 100000 x 100000 pixels would take about"):
        read_image(path)
