"""The measured materials: the Jensen 2001 Fig. 5(b) table as data, and the library
(Jensen 2001 and Narasimhan 2006) with its provenance, checked against second sources."""

import re

import numpy as np
import pytest

from jsss.materials import jensen2001, jensen2001_names, jensen2001_table, material, material_entry, material_names


# ----------------------------------------------------------------------------- Jensen 2001 API
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


# ----------------------------------------------------------------------------- the library
NARASIMHAN = [n for n in material_names() if material_entry(n).source.key == "narasimhan2006"]


def test_at_least_45_materials_with_simple_unique_names():
    """47 materials (12 Jensen, 35 Narasimhan); names are lowercase words joined by underscores."""
    names = material_names()
    assert len(names) >= 45 and len(set(names)) == len(names)
    assert len(NARASIMHAN) == 35
    assert all(re.fullmatch(r"[a-z0-9]+(_[a-z0-9]+)*", n) for n in names), names


@pytest.mark.parametrize("name", material_names())
def test_every_entry_has_its_provenance(name):
    """Source citation, table, units, conversion, where g and eta come from and the uncertainty
    (or that there is none) are all stated; coefficients are non-negative RGB triples and
    sigma_s' = 0 only where the source measured no scattering."""
    e = material_entry(name)
    for field in ("citation", "table", "units", "conversion", "g", "eta", "uncertainty", "transcribed_from"):
        assert len(getattr(e.source, field)) > 10, (name, field)
    assert "1/mm" in e.source.units or "mm^-1" in e.source.units
    assert len(e.sigma_a) == len(e.sigma_s_prime) == len(e.g) == 3
    assert min(e.sigma_a + e.sigma_s_prime) >= 0 and all(-1 < g < 1 for g in e.g)
    assert 1.0 < e.eta < 2.0
    if 0.0 in e.sigma_s_prime:
        assert "no measurable scattering" in e.note


def test_jensen_rows_are_the_jensen2001_table_unchanged():
    """The library's 12 Jensen rows are jensen2001_table()'s numbers (the paper's Fig. 5(b)),
    under the paper's names in lowercase, with g = 0 (the paper gives none)."""
    for row in jensen2001_table():
        e = material_entry(row.name)
        assert e.name == row.name.lower() and e.source.key == "jensen2001"
        assert (e.sigma_a, e.sigma_s_prime, e.eta, e.diffuse_reflectance) == (
            row.sigma_a, row.sigma_s_prime, row.eta, row.diffuse_reflectance)
        assert e.g == (0.0, 0.0, 0.0) and e.sigma_s is None
        a, b = jensen2001(row.name), material(row.name)
        for field in ("sigma_a", "sigma_s_prime", "eta"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def _half_unit(value: float) -> float:
    """Half a unit in the last digit printed: the rounding of a value quoted as ``repr`` shows it
    (a trailing zero the source printed and repr drops only makes the bound looser)."""
    text = repr(float(value))
    if "e" in text:
        mantissa, exponent = text.split("e")
        decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
        return 0.5 * 10.0 ** (int(exponent) - decimals)
    return 0.5 * 10.0 ** -(len(text.split(".")[1]) if "." in text else 0)


@pytest.mark.parametrize("name", NARASIMHAN)
def test_narasimhan_sigma_s_and_g_give_pbrts_reduced_scattering(name):
    """Two renderers transcribed the paper apart: pbrt-v4 prints sigma_s' (5 digits), Mitsuba 0.5
    sigma_s and g. sigma_s (1 - g) must equal sigma_s' within the rounding of the digits each
    printed, in every channel (interval arithmetic on the half units)."""
    e = material_entry(name)
    for s, g, sp in zip(e.sigma_s, e.g, e.sigma_s_prime):
        # Mitsuba prints g to 5 decimals, each a multiple of 0.001 (the paper's 3 decimals):
        # rounding of at most 5e-4 is allowed for it, whatever repr shows ("0.75")
        ds, dg, dsp = _half_unit(s), min(_half_unit(g), 5e-4), _half_unit(sp)
        bound = ds * (1 - g) + s * dg + ds * dg + dsp
        assert abs(s * (1 - g) - sp) <= bound * (1 + 1e-9), (name, s, g, sp, bound)


# pbrt-v2's transcription of the paper's table (src/core/volume.cpp @ e6f6334f3c26, labelled there
# sigma_prime_s and sigma_a; the numbers are the extinction sigma_t and sigma_a at the dilution
# measured): typed here from that file for the materials whose values carry 3-5 digits.
PBRT_V2 = {
    "espresso": ((0.4376, 0.5115, 0.6048), (0.1669, 0.2287, 0.3078)),
    "mint_mocha_coffee": ((0.19, 0.26, 0.35), (0.0984, 0.1519, 0.204)),
    "gatorade": ((0.4009, 0.4185, 0.4324), (0.1617, 0.1258, 0.0579)),
    "clorox": ((0.16, 0.25, 0.33), (0.0175, 0.0777, 0.1372)),
    "ruby_grapefruit_juice": ((0.2513, 0.3517, 0.4305), (0.0896, 0.1911, 0.2636)),
    "white_grapefruit_juice": ((0.3609, 0.38, 0.5632), (0.0096, 0.0131, 0.0395)),
    "head_and_shoulders_shampoo": ((0.3674, 0.4527, 0.5211), (0.0883, 0.1637, 0.2125)),
    "salt_powder": ((0.76, 0.8685, 0.9363), (0.5115, 0.5863, 0.6147)),
    "suisse_mocha_powder": ((0.5098, 0.6476, 0.7944), (0.1875, 0.2893, 0.3796)),
}


@pytest.mark.parametrize("name", sorted(PBRT_V2))
def test_narasimhan_values_are_the_papers_table_scaled_by_one_dilution_factor(name):
    """At natural concentration every coefficient is the diluted one times one factor per
    material (the dilution), the same for absorption and scattering in all three channels:
    sigma_a / sigma_a,diluted and sigma_s / (sigma_t - sigma_a)_diluted agree within the
    rounding of pbrt-v2's 4 decimals (<= 1 %)."""
    sigma_t, sigma_a = (np.asarray(v) for v in PBRT_V2[name])
    e = material_entry(name)
    factors = np.concatenate([np.asarray(e.sigma_a) / sigma_a, np.asarray(e.sigma_s) / (sigma_t - sigma_a)])
    assert factors.max() / factors.min() - 1 < 0.01, (name, factors)


def test_narasimhan_g_is_the_papers_forward_scattering():
    """The g Mitsuba 0.5 carries for these media are forward (0.5-0.99, where they scatter),
    and sigma_s' < sigma_s wherever sigma_s > 0: what a stored sigma_s' (not sigma_s) means."""
    for name in NARASIMHAN:
        e = material_entry(name)
        for s, g, sp in zip(e.sigma_s, e.g, e.sigma_s_prime):
            if s > 0:
                assert 0.5 < g < 1.0 and sp < s, (name, s, g, sp)
        assert 0.5 < e.g_mean < 1.0


def test_names_resolve_as_sources_spell_them_and_keep_jensens_plain_names():
    """'Regular Milk', 'regular-milk' and 'REGULAR_MILK' are one material; 'Head & Shoulders
    Shampoo' reaches its key; marble, ketchup and wholemilk are Jensen's."""
    assert material_entry("Regular Milk") == material_entry("regular-milk") == material_entry("REGULAR_MILK")
    assert material_entry("Head & Shoulders Shampoo").name == "head_and_shoulders_shampoo"
    for name in ("marble", "ketchup", "wholemilk", "Skin1"):
        assert material_entry(name).source.key == "jensen2001"
    np.testing.assert_allclose(material("regular milk").sigma_s_prime, [4.5513, 5.8294, 7.136])


@pytest.mark.parametrize("typed, expected", [("marbel", "marble"), ("milk", "regular_milk"),
                                             ("espreso", "espresso"), ("lowfat chocolate", "lowfat_chocolate_milk")])
def test_unknown_name_names_the_close_ones(typed, expected):
    """A misspelt or partial name raises ValueError naming it and the library names near it."""
    with pytest.raises(ValueError) as info:
        material(typed)
    assert repr(typed) in str(info.value) and expected in str(info.value)


@pytest.mark.parametrize("name", material_names())
def test_every_material_is_a_medium_with_a_finite_total_reflectance(name):
    """Each builds a Medium (float64 and float32) whose dipole R_d lies in [0, 1] in every
    channel, 0 where the source measured no scattering."""
    from jsss.diffusion.dipole import total_reflectance

    e = material_entry(name)
    rd = np.asarray(total_reflectance(material(name)))
    assert rd.shape == (3,) and np.all(np.isfinite(rd)) and np.all((rd >= 0) & (rd <= 1)), (name, rd)
    assert np.all(rd[np.asarray(e.sigma_s_prime) == 0] == 0)
    assert material(name, dtype=np.float32).sigma_a.dtype == np.float32


def test_a_scene_names_a_narasimhan_material_and_renders_it():
    """`[material] name = "regular_milk"` loads with the library's coefficients and renders a
    small frame: finite, lit, and redder than blue as the milk's R_d (R > B) says."""
    import jax.numpy as jnp

    from jsss.render import parse_scene, plan_scene, render
    from tests.jsss.render.scenes import scene_dict

    data = scene_dict(material={"name": "Regular Milk"},
                      camera={"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": [32, 24]},
                      render={"texture_size": 64, "accuracy": 0.1})
    scene = parse_scene(data, source="milk.toml")
    np.testing.assert_allclose(scene.material.medium.sigma_s_prime, [4.5513, 5.8294, 7.136])
    np.testing.assert_allclose(scene.material.eta, 1.33)
    radiance = np.asarray(render(scene, plan_scene(scene, method="lambert"), dtype=jnp.float64).radiance)
    assert np.all(np.isfinite(radiance)) and radiance.max() > 0
    lit = radiance[..., 1] > 0.1 * radiance[..., 1].max()
    assert radiance[lit, 0].sum() > radiance[lit, 2].sum()


def test_a_scene_with_an_unknown_name_names_the_close_ones():
    """The scene's error names the key and the library names near the one given."""
    from jsss.render import SceneError, parse_scene
    from tests.jsss.render.scenes import scene_dict

    data = scene_dict(material={"name": "espreso"})
    with pytest.raises(SceneError, match=r"\[material\] name: unknown material 'espreso'; did you mean espresso"):
        parse_scene(data, source="s.toml")


def test_a_material_with_a_channel_that_does_not_scatter_renders():
    """Merlot scatters in red only (sigma_s' = 0 in G and B): its frame is finite, dark in G, B."""
    import jax.numpy as jnp

    from jsss.render import parse_scene, plan_scene, render
    from tests.jsss.render.scenes import scene_dict

    scene = parse_scene(scene_dict(material={"name": "merlot"}), source="merlot.toml")
    radiance = np.asarray(render(scene, plan_scene(scene, method="lambert"), dtype=jnp.float64).radiance)
    assert np.all(np.isfinite(radiance))
