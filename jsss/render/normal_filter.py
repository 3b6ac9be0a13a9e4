r"""Normal filtering (Patro 2007): subsurface blur folded into the shading normals.

For a Lambertian surface lit by distant light, the irradiance :math:`\max(0, n\cdot l)`
is linear in the normal wherever it is lit, so blurring the *irradiance* with the profile
is blurring the *normals* (up to the clamp and the shadows, which this method ignores:
Patro's noted limit -- no light bleeds across shadow borders). Filtered normals are
computed once per mesh and material; shading then costs what Lambert costs.

Two filters, both per colour channel:

* :func:`smooth_normals` -- the naive one (Patro eq. 3): each vertex normal becomes the
  weighted mean :math:`(\alpha n_i + \sum_j e^{-\sigma_{tr} d_{ij}} n_j)/(\alpha + \sum_j
  e^{-\sigma_{tr} d_{ij}})` over its mesh neighbours, iterated so that the blur reaches
  further than one ring.
* :func:`spectral_filter` -- the spectral one (Patro eqs. 4-11 after Vallet & Levy): the
  normals are expanded in the low-frequency eigenvectors of the mesh's cotangent Laplacian
  (:math:`L\phi = \lambda M\phi`, :math:`M` the lumped vertex areas), each coefficient
  multiplied by a transfer function :math:`F(\omega)` at :math:`\omega = \sqrt\lambda`
  [rad/mm], and the part the eigenvectors miss is scaled by the mean of :math:`F` over the
  remaining band (Patro eq. 11). With the *profile's own* transfer function (its Hankel
  transform over its total) the cut-off is the material's diffusion length, not a tuned
  constant: a Gaussian of variance :math:`v` transfers :math:`e^{-\omega^2 v/2}`.

Eigenvectors are expensive (a sparse shift-invert solve) and depend only on the mesh, so
:func:`laplacian_spectrum` keeps them for the process, keyed by :meth:`Mesh.digest`, and on disk
only where asked (``cache_dir=``, or a folder a console script named with
:func:`keep_spectra_in`): library code writes no file of its own accord.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .kept import save_arrays
from .mesh import Mesh, weld

__all__ = ["Spectrum", "cotangent_laplacian", "keep_spectra_in", "laplacian_spectrum", "smooth_normals",
           "spectral_filter"]

# Where laplacian_spectrum keeps spectra on disk when no cache_dir is given: None (the library's
# default) keeps them in memory only; console scripts name a folder with keep_spectra_in.
_spectra_dir: Path | None = None
_in_memory: dict = {}  # (mesh digest, count) -> Spectrum, the last few meshes of this process
_IN_MEMORY_MESHES = 8


def cotangent_laplacian(vertices, faces):
    r"""Stiffness :math:`L` and lumped mass :math:`M` of the Laplace-Beltrami operator.

    :math:`L_{ij} = -\tfrac12(\cot\beta_{ij} + \cot\beta'_{ij})` for an edge (the angles
    opposite it), :math:`L_{ii} = -\sum_j L_{ij}`; :math:`M_{ii}` is a third of the area of the
    triangles at vertex :math:`i` [mm^2]. :math:`L\phi = \lambda M\phi` approximates
    :math:`-\Delta\phi = \lambda\phi` (Patro's eq. 4 divides by :math:`(\Omega_i+\Omega_j)/2`
    instead, which is not symmetric; the generalised form keeps the eigenvectors
    :math:`M`-orthogonal).

    Returns
    -------
    L : scipy.sparse.csr_matrix (U, U), symmetric positive semi-definite; mass : ndarray (U,)
    """
    import scipy.sparse as sp  # imported here: 0.28 s of every command that renders, normal filtering or not
    v = np.asarray(vertices, float)
    f = np.asarray(faces)
    n = len(v)
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, o = f[:, (k + 1) % 3], f[:, (k + 2) % 3], f[:, k]  # edge (i, j) opposite vertex o
        a, b = v[i] - v[o], v[j] - v[o]
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        cot = (a * b).sum(1) / np.maximum(cross, 1e-300)
        rows += [i, j]
        cols += [j, i]
        vals += [-0.5 * cot, -0.5 * cot]
    off = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    L = off - sp.diags(np.asarray(off.sum(1)).ravel())
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    mass = np.bincount(f.ravel(), np.repeat(area / 3, 3), minlength=n)
    return L.tocsr(), mass


@dataclass(frozen=True, eq=False)
class Spectrum:
    """The lowest eigenpairs of a mesh's Laplacian (welded), with what maps them to its vertices.

    Attributes
    ----------
    eigenvalues : (k,) [1/mm^2], ascending, the first 0
    eigenvectors : (U, k), M-orthonormal
    mass : (U,) [mm^2]; index : (V,) welded vertex of each mesh vertex
    nyquist : float [rad/mm], pi over the mean edge length (the highest frequency the mesh holds)
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    mass: np.ndarray
    index: np.ndarray
    nyquist: float


def _compute_spectrum(mesh: Mesh, count: int) -> Spectrum:
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    positions, index, faces = weld(mesh)
    L, mass = cotangent_laplacian(positions, faces)
    k = min(count, len(positions) - 1)
    # Shift-invert just below 0 (L is singular): the solver converges on the smallest eigenvalues.
    values, vectors = spla.eigsh(L, k=k, M=sp.diags(mass), sigma=-1e-6 * L.diagonal().mean(), which="LM")
    order = np.argsort(values)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    mean_edge = float(np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1).mean())
    return Spectrum(np.maximum(values[order], 0.0), vectors[:, order], mass, index, np.pi / mean_edge)


def keep_spectra_in(folder) -> None:
    """Keep spectra under ``folder/spectra/`` from now on (console scripts; None: memory only)."""
    global _spectra_dir
    _spectra_dir = None if folder is None else Path(folder)


def laplacian_spectrum(mesh: Mesh, count: int = 128, *, cache_dir=None) -> Spectrum:
    """The ``count`` lowest eigenpairs of ``mesh``'s cotangent Laplacian.

    Kept for the process (the last 8 meshes), and on disk where asked: in
    ``<cache_dir>/spectra/<mesh digest>-<count>.npz`` (``cache_dir``, else the folder given to
    :func:`keep_spectra_in`), written atomically; an unreadable cache file is recomputed (with a
    warning) and replaced.
    """
    if count < 1:
        raise ValueError(f"count must be >= 1 eigenpairs; got {count}.")
    key = (mesh.digest(), count)
    folder = cache_dir if cache_dir is not None else _spectra_dir
    path = None if folder is None else Path(folder) / "spectra" / f"{key[0]}-{count}.npz"
    if path is None and key in _in_memory:
        return _in_memory[key]
    if path is not None and path.is_file():
        try:
            with np.load(path) as data:
                return Spectrum(data["eigenvalues"], data["eigenvectors"], data["mass"], data["index"],
                                float(data["nyquist"]))
        except (OSError, ValueError, KeyError) as error:
            warnings.warn(f"{path}: unreadable spectrum cache ({error}); recomputing.", stacklevel=2)
    spectrum = _compute_spectrum(mesh, count)
    if path is None:
        if len(_in_memory) >= _IN_MEMORY_MESHES:
            _in_memory.pop(next(iter(_in_memory)))
        _in_memory[key] = spectrum
        return spectrum
    try:
        _write_atomically(path, spectrum)
    except OSError as error:  # a read-only cache folder must not stop a render
        warnings.warn(f"{path}: could not cache the spectrum ({error}); set JSSS_CACHE_DIR to a "
                      "writable folder to keep it.", stacklevel=2)
    return spectrum


def _write_atomically(path: Path, spectrum: Spectrum) -> None:
    save_arrays(path, {"eigenvalues": spectrum.eigenvalues, "eigenvectors": spectrum.eigenvectors,
                       "mass": spectrum.mass, "index": spectrum.index, "nyquist": spectrum.nyquist})


def spectral_filter(spectrum: Spectrum, signal, transfer) -> np.ndarray:
    r"""Filter a per-vertex signal (V, D) with ``transfer(omega)`` -> (..., C) per channel.

    Coefficients :math:`\eta = \Phi^T M s` (on welded vertices, mass-weighted mean of a
    vertex's copies), reconstruction :math:`\Phi F(\omega)\eta`, plus the residual
    :math:`s - \Phi\eta` scaled by :math:`\gamma`, the mean of :math:`F` over
    :math:`[\omega_m, \omega_{Nyquist}]` (Patro eq. 11). ``transfer = 1`` returns the signal
    exactly. Returns (V, C, D).
    """
    signal = np.asarray(signal, float)
    counts = np.bincount(spectrum.index, minlength=len(spectrum.mass)).astype(float)
    welded = np.zeros((len(spectrum.mass), signal.shape[1]))
    np.add.at(welded, spectrum.index, signal)
    welded /= np.maximum(counts, 1)[:, None]
    phi = spectrum.eigenvectors
    coefficients = phi.T @ (spectrum.mass[:, None] * welded)  # (k, D)
    omega = np.sqrt(spectrum.eigenvalues)
    gain = np.atleast_2d(np.asarray(transfer(omega), float).T).T  # (k, C)
    if gain.shape[0] != len(omega):
        raise ValueError(f"transfer must return one row per eigenvalue ({len(omega)}); got shape {gain.shape}.")
    band = np.linspace(omega[-1], max(spectrum.nyquist, omega[-1]), 256)
    gamma = np.atleast_2d(np.asarray(transfer(band), float).T).T.mean(0)  # (C,)
    low = phi @ coefficients  # (U, D)
    residual = signal - low[spectrum.index]  # per mesh vertex: keeps hard edges' copies apart
    filtered = np.einsum("uk,kc,kd->ucd", phi, gain, coefficients)[spectrum.index]
    return filtered + gamma[None, :, None] * residual[:, None, :]


def smooth_normals(mesh: Mesh, sigma_tr, *, iterations: int = 1, alpha: float = 0.5) -> np.ndarray:
    r"""Patro's naive filter: iterated neighbour means weighted by :math:`e^{-\sigma_{tr} d}`.

    Parameters
    ----------
    mesh : Mesh
    sigma_tr : array_like (C,) [1/mm]
        Effective transport coefficient per channel.
    iterations : int
        Each pass reaches one ring further.
    alpha : float > 0
        Weight of a vertex's own normal.

    Returns
    -------
    (V, C, 3) filtered normals (not renormalised: their length carries the attenuation).
    """
    import scipy.sparse as sp
    if iterations < 0 or alpha <= 0:
        raise ValueError(f"iterations must be >= 0 and alpha > 0; got {iterations}, {alpha}.")
    positions, index, faces = weld(mesh)
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1), axis=0)
    length = np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1)
    sigma = np.atleast_1d(np.asarray(sigma_tr, float))
    n_welded = len(positions)
    counts = np.bincount(index, minlength=n_welded).astype(float)
    out = []
    for s in sigma:
        w = np.exp(-s * length)
        A = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([edges[:, 0], edges[:, 1]]),
                                                    np.concatenate([edges[:, 1], edges[:, 0]]))),
                          shape=(n_welded, n_welded)).tocsr() + alpha * sp.identity(n_welded)
        norm = np.asarray(A.sum(1)).ravel()
        welded = np.zeros((n_welded, 3))
        np.add.at(welded, index, mesh.normals)
        welded /= counts[:, None]
        smoothed = welded
        for _ in range(iterations):
            smoothed = (A @ smoothed) / norm[:, None]
        # Hard edges keep their own copies: add the smoothing's change to each copy's normal.
        out.append(mesh.normals + (smoothed - welded)[index])
    return np.stack(out, 1)
