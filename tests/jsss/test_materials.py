"""The Jensen 2001 Fig. 5(b) table as data."""

import numpy as np
import pytest

from jsss.materials import jensen2001, jensen2001_names, jensen2001_table


def test_twelve_materials_in_paper_order():
    """Twelve rows, Spectralon included, with RGB triples."""
    names = jensen2001_names()
    assert len(names) == 12 and names[0] == "Apple" and "Spectralon" in names
    assert all(len(row.sigma_a) == 3 for row in jensen2001_table())


def test_names_are_case_insensitive_and_values_are_the_table():
    """'MARBLE', 'marble' and 'Marble' give the same medium with the published numbers."""
    m = jensen2001("MARBLE")
    np.testing.assert_allclose(m.sigma_s_prime, [2.19, 2.62, 3.00])
    np.testing.assert_allclose(m.sigma_a, [0.0021, 0.0041, 0.0071])
    np.testing.assert_allclose(m.eta, 1.5)
    np.testing.assert_array_equal(jensen2001("marble").sigma_a, m.sigma_a)


def test_unknown_name_lists_the_valid_ones():
    """An unknown name raises ValueError that names it and lists every valid name."""
    with pytest.raises(ValueError) as info:
        jensen2001("jade")
    message = str(info.value)
    assert "'jade'" in message and all(name in message for name in jensen2001_names())


def test_console_script_prints_every_material(capsys):
    """The interim `jsss` command prints one line per material with both columns."""
    from jsss.cli import main

    assert main([]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in jensen2001_names())
    assert "0.1264" in out  # Chicken1 blue, the one channel off by more than 0.01


def test_info_reports_versions_caches_precision_and_devices(monkeypatch, tmp_path):
    """`jsss info` names what a bug report needs, with the cache directories the environment sets."""
    import jax

    from jsss.cli import info_lines

    monkeypatch.setenv("JSSS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "xla"))
    info = dict(line.split(": ", 1) for line in info_lines())
    assert info["jax"] == jax.__version__
    for key in ("jsss", "numpy", "OpenEXR", "devices"):
        assert info[key] and info[key] != "not installed"
    assert info["float64 (jax_enable_x64)"].startswith("on")  # the test suite enables it
    assert info["jsss cache (JSSS_CACHE_DIR)"] == str(tmp_path / "cache")
    assert info["compilation cache of the commands (JAX_COMPILATION_CACHE_DIR)"] == str(tmp_path / "xla")
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR")
    info = dict(line.split(": ", 1) for line in info_lines())
    assert info["compilation cache of the commands (JAX_COMPILATION_CACHE_DIR)"] == str(tmp_path / "cache" / "xla")
    assert "cpu" in info["devices"]
