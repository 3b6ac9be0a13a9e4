"""EXR input/output: round trips and errors that name the file."""

import numpy as np
import pytest

from measure.exr import ExrError, read_exr, write_exr


def test_float_round_trip_is_exact_and_keeps_attributes(tmp_path):
    """float32 pixels come back bit-exact, with channel names and header attributes."""
    pixels = np.random.default_rng(0).random((7, 9, 3)).astype(np.float32)
    path = write_exr(tmp_path / "a.exr", pixels, ("R", "G", "B"), attributes={"jsss_pixel_mm": 0.05, "note": "x"})
    image = read_exr(path)
    np.testing.assert_array_equal(image.pixels, pixels.astype(np.float64))
    assert image.channels == ("R", "G", "B")
    assert image.header["jsss_pixel_mm"] == pytest.approx(0.05, rel=1e-7)
    assert image.header["note"] == "x"


def test_half_round_trip_within_half_precision(tmp_path):
    """half pixels round to float16 (relative error <= 2^-11) and a Y image reads as one channel."""
    pixels = np.random.default_rng(1).uniform(0.01, 100, (5, 6))
    image = read_exr(write_exr(tmp_path / "y.exr", pixels, ("Y",), pixel_type="half"))
    assert image.channels == ("Y",)
    np.testing.assert_allclose(image.pixels[..., 0], pixels, rtol=2.0**-11)


def test_errors_name_the_file(tmp_path):
    """Missing file, garbage file, missing channel and NaN pixels raise ExrError naming the path."""
    with pytest.raises(ExrError, match="nope.exr: no such file"):
        read_exr(tmp_path / "nope.exr")
    garbage = tmp_path / "garbage.exr"
    garbage.write_text("not an exr")
    with pytest.raises(ExrError, match="garbage.exr: not a readable OpenEXR"):
        read_exr(garbage)
    path = write_exr(tmp_path / "y.exr", np.ones((3, 3)), ("Y",))
    with pytest.raises(ExrError, match=r"y.exr: missing channel\(s\) \['R'\]"):
        read_exr(path, ("R",))
    bad = np.ones((3, 3, 3))
    bad[1, 1, 2] = np.nan
    path = write_exr(tmp_path / "nan.exr", bad)
    with pytest.raises(ExrError, match="nan.exr: 1 NaN/Inf"):
        read_exr(path)
    assert np.isnan(read_exr(path, allow_nonfinite=True).pixels).sum() == 1


def test_write_is_atomic_and_checks_shapes(tmp_path):
    """A shape/channel mismatch raises before anything is written; no temp files remain."""
    with pytest.raises(ExrError, match="do not match"):
        write_exr(tmp_path / "x.exr", np.ones((3, 3, 2)), ("R", "G", "B"))
    write_exr(tmp_path / "ok.exr", np.ones((3, 3, 3)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.exr"]
