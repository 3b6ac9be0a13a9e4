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
