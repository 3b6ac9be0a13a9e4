"""Normal filtering (Patro 2007): the Laplacian's spectrum, the filters, the cache."""

import warnings

import numpy as np
import pytest

from jsss.render.mesh import box, plane, uv_sphere
from jsss.render.normal_filter import (cotangent_laplacian, laplacian_spectrum, smooth_normals, spectral_filter,
                                       weld)


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("JSSS_CACHE_DIR", str(tmp_path))


def _ones(omega):
    return np.ones(np.shape(omega) + (3,))


def test_laplacian_first_eigenvalue_is_zero_with_a_constant_eigenvector():
    for mesh in (uv_sphere(1.0, segments=32, rings=16), box((20.0, 10.0, 5.0), segments=4)):
        s = laplacian_spectrum(mesh, 8)
        assert abs(s.eigenvalues[0]) < 1e-8 * s.eigenvalues[1]
        first = s.eigenvectors[:, 0]
        assert np.ptp(first) < 1e-8 * np.abs(first).max()
        assert (s.mass * first**2).sum() == pytest.approx(1.0)  # M-orthonormal
        L, mass = cotangent_laplacian(*weld(mesh)[::2])
        assert abs(L - L.T).max() < 1e-12 and np.allclose(L @ np.ones(len(mass)), 0, atol=1e-12)


def test_sphere_eigenvalues_come_in_spherical_harmonic_multiplicities():
    """On the unit sphere -Laplace has eigenvalues l(l+1) with multiplicity 2l+1."""
    s = laplacian_spectrum(uv_sphere(1.0, segments=64, rings=32), 36)
    ell = np.rint((-1 + np.sqrt(1 + 4 * s.eigenvalues)) / 2).astype(int)
    assert np.array_equal(np.bincount(ell), [1, 3, 5, 7, 9, 11])
    assert np.allclose(s.eigenvalues, ell * (ell + 1), rtol=0.03, atol=1e-8)


@pytest.mark.parametrize("mesh", [uv_sphere(10.0, segments=32, rings=16), box(segments=3)], ids=["sphere", "box"])
def test_spectral_filter_with_infinite_cutoff_returns_the_normals(mesh):
    s = laplacian_spectrum(mesh, 16)
    out = spectral_filter(s, mesh.normals, _ones)
    assert out.shape == (len(mesh.vertices), 3, 3)
    assert np.abs(out - mesh.normals[:, None]).max() < 1e-12  # box corners keep each face's normal


def test_gaussian_transfer_shrinks_a_spheres_normals_by_the_heat_kernel():
    """Sphere normals are l = 1 harmonics (eigenvalue 2/R^2): a Gaussian of variance v
    transfers exp(-omega^2 v / 2), so they shrink by exp(-v / R^2) exactly."""
    radius, variance = 10.0, np.array([1.0, 10.0, 40.0])
    mesh = uv_sphere(radius, segments=64, rings=32)
    s = laplacian_spectrum(mesh, 16)
    out = spectral_filter(s, mesh.normals, lambda w: np.exp(-np.asarray(w)[..., None] ** 2 * variance / 2))
    expected = np.exp(-variance / radius**2)
    lengths = np.linalg.norm(out, axis=-1)  # (V, 3 channels)
    assert np.allclose(np.median(lengths, 0), expected, rtol=0.01)
    direction = out / lengths[..., None]
    assert np.min((direction * mesh.normals[:, None]).sum(-1)) > 0.999


def test_naive_smoothing_keeps_a_plane_and_blurs_shorter_diffusion_less():
    flat = plane(10.0, segments=6)
    assert np.allclose(smooth_normals(flat, [0.5, 1.0, 2.0], iterations=5), flat.normals[:, None])
    sphere = uv_sphere(10.0, segments=32, rings=16)
    lengths = np.linalg.norm(smooth_normals(sphere, [0.05, 0.5, 5.0], iterations=10), axis=-1).mean(0)
    assert lengths[0] < lengths[1] < lengths[2] < 1.0  # long diffusion (small sigma_tr) blurs most
    once, more = (np.linalg.norm(smooth_normals(sphere, [0.1], iterations=k), axis=-1).mean() for k in (1, 8))
    assert more < once


def test_spectrum_is_cached_on_disk_by_mesh_digest(tmp_path, monkeypatch):
    import jsss.render.normal_filter as nf

    mesh = uv_sphere(5.0, segments=16, rings=8)
    first = laplacian_spectrum(mesh, 6, cache_dir=tmp_path)
    path = tmp_path / "spectra" / f"{mesh.digest()}-6.npz"
    assert path.is_file()
    monkeypatch.setattr(nf, "_compute_spectrum", lambda *a: pytest.fail("recomputed despite the cache"))
    again = laplacian_spectrum(mesh, 6, cache_dir=tmp_path)
    assert np.array_equal(again.eigenvalues, first.eigenvalues)
    monkeypatch.undo()
    path.write_bytes(b"not a zip")
    monkeypatch.setattr(nf, "_spectra_dir", tmp_path)  # what keep_spectra_in sets for the console scripts
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recovered = laplacian_spectrum(mesh, 6)
    assert any("unreadable spectrum cache" in str(w.message) for w in caught)
    assert np.allclose(recovered.eigenvalues, first.eigenvalues)
    assert np.load(path)["eigenvalues"].shape == (6,)  # replaced with a good file


def test_the_library_writes_no_spectrum_file_unless_asked(tmp_path, monkeypatch):
    """Without cache_dir or keep_spectra_in, spectra stay in memory: no file under HOME, XDG or JSSS_CACHE_DIR."""
    import jsss.render.normal_filter as nf

    for name in ("HOME", "XDG_CACHE_HOME", "JSSS_CACHE_DIR"):
        monkeypatch.setenv(name, str(tmp_path / name))
    # as a library user's process: no console command (an earlier test's, in this worker) named a folder
    monkeypatch.setattr(nf, "_spectra_dir", None)
    mesh = uv_sphere(4.0, segments=12, rings=6)
    first = laplacian_spectrum(mesh, 5)
    assert not any(tmp_path.rglob("*"))
    monkeypatch.setattr(nf, "_compute_spectrum", lambda *a: pytest.fail("recomputed within the process"))
    assert laplacian_spectrum(mesh, 5) is first


def test_bad_arguments_are_named():
    mesh = uv_sphere(5.0, segments=16, rings=8)
    with pytest.raises(ValueError, match="count"):
        laplacian_spectrum(mesh, 0)
    with pytest.raises(ValueError, match="iterations"):
        smooth_normals(mesh, [0.1], iterations=-1)
    s = laplacian_spectrum(mesh, 4)
    with pytest.raises(ValueError, match="one row per eigenvalue"):
        spectral_filter(s, mesh.normals, lambda w: np.ones((2, 3)))
