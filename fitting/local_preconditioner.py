r"""A preconditioner for an albedo map's normal equations, from the Jacobian's local part.

A pre-post colour map enters a texture-space frame twice (d'Eon 2007 sec. 5.3),
:math:`L_p = P\,[\sqrt{c}\;R * (\sqrt{c}\,E)]`, with :math:`P` the pixels' bilinear lookup. In
:math:`u = \ln c` the Jacobian is :math:`J = J_\text{exit} + J_\text{entry}`:

* :math:`J_\text{exit} = \tfrac12 P\,\mathrm{diag}(M)` (the colour layer on the way out) is
  *local*: a texel moves only the pixels that look it up, a few texels around it;
* :math:`J_\text{entry} = \tfrac12 P\,\mathrm{diag}(\sqrt{c})\,R * \mathrm{diag}(\sqrt{c}\,E)`
  spreads over the profile's width. For a map pattern finer than the profile the blur averages it
  away (:math:`J \approx J_\text{exit}`); for one coarser than the profile it acts as
  :math:`J_\text{exit}` does (:math:`J \approx 2 J_\text{exit}`).

So :math:`A = J^T J` lies between :math:`J_\text{exit}^T J_\text{exit}` and four times it, and
:math:`M = 2\,J_\text{exit}^T J_\text{exit}` puts the preconditioned spectrum within about
[1/2, 2]: conjugate gradients then converge in a number of iterations that no longer grows with
the map's size or its poorly seen directions (the map's finest checkerboard, which the bilinear
lookups average out, is as poorly seen in :math:`M` as in :math:`A`). :math:`M` is sparse
(a texel couples to texels at most three apart), formed exactly from a few Jacobian-vector
products of the exit part alone (no blur), and factorised once per Gauss-Newton step by
:func:`scipy.sparse.linalg.splu`.

Texels that the pixels barely look up but whose light still diffuses into seen pixels (at the
view's edge) have :math:`A_{tt} \gg M_{tt}`; their diagonal is raised to :math:`A`'s where it is
given. The mean free paths' block is :math:`A`'s own diagonal.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

__all__ = ["LocalPreconditioner", "local_probes", "texel_columns"]

# Texels apart that share a probe of the exit part: a texel reaches texture texels one map texel
# away and pixels half a texture texel beyond them, so two texels three apart never share a pixel.
# A power of two, so the lattice stays regular across a UV seam that wraps a power-of-two map.
PROBE_SPACING = 4
# The low-frequency end of J^T J is 4 J_exit^T J_exit and the high-frequency end 1 x: 2 is their middle
EXIT_SCALE = 2.0


def local_probes(shape, spacing: int = PROBE_SPACING) -> np.ndarray:
    """Probe maps (2, spacing^2, H_m, W_m, 3): per lattice colour, its texels' indicator and the
    indicator times (texel index + 1), whose ratio in a pixel names the texel that moved it."""
    rows, cols = np.indices(shape)
    index = (rows * shape[1] + cols + 1).astype(float)
    colours = [((rows % spacing == i) & (cols % spacing == j)) for i in range(spacing) for j in range(spacing)]
    ones = np.stack([np.repeat(c[..., None], 3, -1).astype(float) for c in colours])
    return np.stack([ones, ones * index[..., None]])


def texel_columns(values: np.ndarray, n_texels: int):
    """The exit part's columns, per channel, from the probes' Jacobian-vector products.

    ``values`` (2, colours, n_residuals) are J_exit applied to :func:`local_probes`' maps, the
    residuals ordered (pixel, channel). Returns a list of three CSR matrices (n_pixels,
    n_texels), or None when two texels of one colour moved one pixel (a UV layout whose charts
    put texels of one colour side by side: the caller falls back to the diagonal)."""
    ones, ids = values
    n_pixels = ones.shape[1] // 3
    out = []
    for k in range(3):
        rows, cols, vals = [], [], []
        for one, idx in zip(ones[:, k::3], ids[:, k::3]):
            hit = np.flatnonzero(one != 0)
            ratio = idx[hit] / one[hit]
            texel = np.rint(ratio)
            if np.any(np.abs(ratio - texel) > 1e-6 * np.maximum(texel, 1.0)) or np.any(texel < 1) \
                    or np.any(texel > n_texels):
                return None
            rows.append(hit)
            cols.append(texel.astype(np.int64) - 1)
            vals.append(one[hit])
        out.append(sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                 shape=(n_pixels, n_texels)))
    return out


class LocalPreconditioner:
    r""":math:`M^{-1}` for the map's normal equations (module docstring), on the scaled system.

    Parameters
    ----------
    columns : list of 3 sparse (n_pixels, n_texels)
        :func:`texel_columns`: the exit part of the whitened residuals' Jacobian, per channel.
    free : (H_m, W_m) bool
        The fitted texels (the operator is the identity on the others).
    diagonal_u : (H_m, W_m, 3), optional
        :math:`A`'s diagonal on the texels; where above :math:`M`'s, :math:`M`'s is raised to it.
    diagonal_ell : (3,)
        :math:`A`'s diagonal on the mean free paths.
    damping : float
        Levenberg-Marquardt's: :math:`M + \lambda\,\mathrm{diag}(A)` for the system
        :math:`A + \lambda\,\mathrm{diag}(A)` (``diagonal_u`` then required).
    """

    def __init__(self, columns, free, diagonal_u, diagonal_ell, damping: float = 0.0):
        self.shape = free.shape
        self.free = np.flatnonzero(free.reshape(-1))
        self.diagonal_ell = np.asarray(diagonal_ell, float)
        self.damping = float(damping)
        self.factors = []
        for k, J in enumerate(columns):
            J = J[:, self.free]
            M = (EXIT_SCALE * (J.T @ J)).tocsc()
            d = M.diagonal()
            raise_to = d if diagonal_u is None else np.maximum(d, np.asarray(diagonal_u)[..., k].reshape(-1)[self.free])
            # A texel no fitted pixel moves through the exit (its light only diffuses in) keeps A's diagonal;
            # a floor of 1e-12 of the typical keeps M invertible where both vanish
            floor = 1e-12 * max(float(np.median(raise_to[raise_to > 0])) if np.any(raise_to > 0) else 1.0, 1e-300)
            M = M + sp.diags(np.maximum(raise_to, floor) - d)
            if damping:
                M = M + sp.diags(damping * np.asarray(diagonal_u)[..., k].reshape(-1)[self.free])
            self.factors.append(splu(M.tocsc(), permc_spec="COLAMD"))

    def solve(self, u: np.ndarray, ell: np.ndarray):
        """:math:`M^{-1}` applied to (u (H_m, W_m, 3), ell (3,)): the identity on texels not fitted."""
        u = np.array(u, dtype=float, copy=True)
        flat = u.reshape(-1, 3)
        for k, lu in enumerate(self.factors):
            flat[self.free, k] = lu.solve(flat[self.free, k])
        return flat.reshape(u.shape), np.asarray(ell, float) / ((1 + self.damping) * self.diagonal_ell)
