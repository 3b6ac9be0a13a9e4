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
    with pytest.raises(ExrError, match="garbage.exr: not an OpenEXR file"):
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


# -- hostile files (issue 38 part 6) --------------------------------------------------------------


def _forged(tmp_path, width, height, keep_bytes=None):
    """A real EXR whose header is rewritten to declare ``width`` x ``height`` pixels."""
    import struct

    write_exr(tmp_path / "real.exr", np.ones((4, 4, 3)))
    data = (tmp_path / "real.exr").read_bytes()
    at = data.index(b"box2i", data.index(b"dataWindow")) + len(b"box2i\0") + 4
    data = data[:at] + struct.pack("<4i", 0, 0, width - 1, height - 1) + data[at + 16:]
    path = tmp_path / "forged.exr"
    path.write_bytes(data if keep_bytes is None else data[:keep_bytes])
    return path


def test_a_header_declaring_more_pixels_than_memory_is_refused_before_reading(tmp_path, monkeypatch):
    """A 598-byte file declaring 100000^2 pixels had asked for 37 GiB."""
    monkeypatch.setenv("JSSS_MEMORY_LIMIT", str(8 << 30))
    path = _forged(tmp_path, 100_000, 100_000, keep_bytes=598)
    with pytest.raises(ExrError, match=r"forged.exr: its header's 100000 x 100000 pixels x 3 channel\(s\) would take"):
        read_exr(path)


@pytest.mark.parametrize("cut, message", [
    (200, "truncated or not an OpenEXR file"),        # inside the header
    (None, None),                                      # whole: reads
    (-40, "truncated or not a readable OpenEXR file"),  # inside the pixels
])
def test_a_truncated_file_says_so(tmp_path, cut, message):
    write_exr(tmp_path / "a.exr", np.random.default_rng(0).random((16, 16, 3)))
    data = (tmp_path / "a.exr").read_bytes()
    (tmp_path / "cut.exr").write_bytes(data if cut is None else data[:cut])
    if message is None:
        assert read_exr(tmp_path / "cut.exr").pixels.shape == (16, 16, 3)
    else:
        with pytest.raises(ExrError, match=f"cut.exr: {message}"):
            read_exr(tmp_path / "cut.exr")


def test_not_an_exr_and_alpha_only_are_named(tmp_path):
    (tmp_path / "text.exr").write_text("hello")
    with pytest.raises(ExrError, match="text.exr: not an OpenEXR file"):
        read_exr(tmp_path / "text.exr")
    write_exr(tmp_path / "alpha.exr", np.ones((4, 4, 1)), channels=("A",))
    with pytest.raises(ExrError, match=r"alpha.exr: holds only an alpha channel \(A\)"):
        read_exr(tmp_path / "alpha.exr")


def test_what_the_exr_library_prints_is_captured_and_kept_off_stdout(capfd):
    """OpenEXR's C++ library prints to stdout (where it corrupted --json) and to stderr (a second
    line before the command's one-line error): both are captured while it reads, for the error
    message to quote or, after a good read, for stderr."""
    import os

    from measure.exr import _library_output

    with _library_output() as printed:
        os.write(1, b"OpenEXR says something\n")
        os.write(2, b"and something else\n")
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert "OpenEXR says something" in printed[0] and "and something else" in printed[0]