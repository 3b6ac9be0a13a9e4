"""`jsss materials`: the measured-material library on the command line, and every material
exported to the three renderers (measure.export)."""

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from jsss.materials import jensen2001_table, material, material_entry, material_names
from measure import export
from measure.commands import info


def _run(*args):
    return subprocess.run([sys.executable, "-m", "measure.commands.info", "materials", *args], capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=300)


def test_jsss_materials_lists_every_material():
    """Exit 0 and one row per material (>= 45), each starting with its name and ending in three R_d."""
    out = _run()
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if line.split(" ", 1)[0] in material_names()]
    assert len(rows) == len(material_names()) >= 45
    assert {row.split(" ", 1)[0] for row in rows} == set(material_names())
    assert "Narasimhan 2006" in out.stdout and "Jensen 2001" in out.stdout


def test_jsss_materials_unknown_name_is_one_line_and_exit_2():
    """A misspelt name: status 2 and one line on stderr naming it and the close library names."""
    out = _run("marbel")
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.count("\n") == 1 and "'marbel'" in out.stderr and "marble" in out.stderr, out.stderr


def test_jsss_materials_name_prints_the_provenance(capsys):
    """One entry: its coefficients, g, eta, the citation, table, units, conversion and uncertainty."""
    assert info.main(["materials", "Regular Milk"]) == 0
    out = capsys.readouterr().out
    for text in ("regular_milk", "Narasimhan", "Acquiring Scattering Properties", "4.5513 5.8294 7.136",
                 "18.2052 20.3826 22.3698", "0.75 0.714 0.681", "1.33", "uncertainty", "conversion", "pbrt-v4"):
        assert text in out, text


def test_jsss_materials_json_is_every_record(capsys):
    """--json: a list of records, one per material, with the provenance fields and finite R_d."""
    assert info.main(["materials", "--json"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in records] == list(material_names())
    for r in records:
        assert r["citation"] and r["units"] and r["conversion"] and r["uncertainty"]
        assert np.all(np.isfinite(r["total_reflectance"]))


def test_total_reflectance_of_jensens_materials_is_the_published_one():
    """R_d from the transport tables (exact to transport) with the paper's sigma_a, sigma_s', eta
    is within 0.02 of the total reflectance Jensen et al. measured and print beside them."""
    for row in jensen2001_table():
        rd, models, g = info.material_reflectance(row.name)
        assert models == ("transport",) * 3 and g == 0.0
        np.testing.assert_allclose(rd, row.diffuse_reflectance, atol=0.02, err_msg=row.name)


def test_reflectance_of_a_channel_without_scattering_is_zero_and_absorbing_ones_use_the_dipole():
    """Merlot scatters in red only (G, B: sigma_s' = 0 in both sources); its red absorbs more
    than the tables cover (sigma_a / sigma_s' > 1000), so the dipole gives it."""
    rd, models, _ = info.material_reflectance("merlot")
    assert models == ("dipole", "none", "none") and rd[1] == rd[2] == 0 and 0 < rd[0] < 1e-3


def test_reflectance_takes_the_tabulated_g_nearest_the_materials():
    """Espresso (mean g 0.894) is read from the g = 0.9 table, white grapefruit juice (0.553)
    from g = 0.5; at espresso's low albedo that matters: R_d at g = 0.9 is below half the g = 0
    value for the same sigma_s' (similarity holds only where scattering dominates)."""
    rd, models, g = info.material_reflectance("espresso")
    assert g == 0.9 and models == ("transport",) * 3
    assert info.material_reflectance("white_grapefruit_juice")[2] == 0.5
    rd0, _, _ = info.material_reflectance("espresso", g=0.0)
    assert np.all(rd < 0.5 * rd0)


@pytest.mark.parametrize("name", material_names())
def test_every_material_exports_to_the_three_renderers(name):
    """Mitsuba 3 dict, pbrt-v4 material and Cycles' Principled inputs, with the material's g;
    finite numbers throughout. Cycles' colour may warn (R_d above what its walk returns)."""
    entry, medium = material_entry(name), material(name)
    d = export.mitsuba_dict(medium, g=entry.g_mean)
    assert d["interior"]["phase"]["g"] == pytest.approx(entry.g_mean) and d["bsdf"]["int_ior"] == pytest.approx(entry.eta)
    assert np.all(np.isfinite(d["interior"]["albedo"]["value"])) and d["interior"]["scale"] > 0
    text = export.pbrt_material(medium, g=entry.g_mean, name=name)
    assert f'MakeNamedMaterial "{name}"' in text and "nan" not in text
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="total reflectance .* is above", category=UserWarning)
        p = export.blender_principled(medium, g=entry.g_mean)
    assert np.all(np.isfinite(p["base_color"])) and np.all(np.isfinite(p["subsurface_radius"]))
