"""The albedo map's preconditioner (fitting.local_preconditioner) against the Jacobian formed in full.

On a small map the whole Jacobian of the fit's whitened residuals is formed column by column
(forward mode, one product per unknown); the probed exit part, the preconditioned spectrum and
the damped step's conjugate-gradient count are checked against it.
"""

import tomllib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting import albedo_map
from fitting.local_preconditioner import LocalPreconditioner, texel_columns
from jsss.render import parse_scene
from tests.fitting.test_albedo_map import SCENE

MAP = 8


@pytest.fixture(scope="module")
def system():
    """A fit's model at the scene's own medium and a start map; its exact Jacobian in u and in
    the colour layer's exit alone, and the fitted texels."""
    scene = parse_scene(tomllib.loads(SCENE.replace("[64, 48]", "[32, 24]").replace("= 64", "= 32")),
                        source="plane.toml")
    rows, cols = np.indices((24, 32))
    photo = 0.02 * (1.5 + np.sin(rows / 3.0)[..., None] * np.cos(cols / 4.0)[..., None]) * np.ones(3)
    medium = scene.material.medium
    sigma_t = np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime)
    ell = jnp.log(jnp.asarray(1 / sigma_t))
    albedo_prime = jnp.asarray(np.asarray(medium.sigma_s_prime) / sigma_t)
    model = albedo_map._Model([(scene, photo)], [photo], [np.ones((24, 32), bool)], (0.01 * photo,), np.ones(1),
                              (MAP, MAP), ell, albedo_prime, jnp.full(3, 1.4), 0.001, True,
                              scene.material.profile_model, scene.material.g, jnp.float64, None, 1e-3, 500, True)
    u = model.start_map(ell, 0.5)
    x = {"u": u + 0.1 * jnp.sin(jnp.arange(u.size).reshape(u.shape)), "ell": ell}
    eye = jnp.eye(u.size).reshape((-1,) + u.shape)
    _, full = jax.linearize(lambda v: model._raw({"u": v, "ell": ell}, model.views), x["u"])

    def exit_only(v):
        parts = [((model._radiance(v, ell, view, static, u_entry=x["u"]) - view.target) * view.inverse_sigma)
                 .reshape(-1) for view, static in zip(model.views, model.statics)]
        return albedo_map._huber(jnp.concatenate(parts))

    _, exit_jvp = jax.linearize(exit_only, x["u"])
    J = np.asarray(jax.lax.map(full, eye)).T.reshape(-1, MAP * MAP, 3)
    J_exit = np.asarray(jax.lax.map(exit_jvp, eye)).T.reshape(-1, MAP * MAP, 3)
    return model, x, J, J_exit


def test_probed_exit_columns_are_the_exit_jacobian(system):
    """Sixteen colours of probes, each texel named by the ratio of two products: every column of
    the exit part's Jacobian comes back, to rounding, and none of the entry part's blur."""
    model, x, J, J_exit = system
    columns = texel_columns(np.asarray(model._local_columns(x, model.views, model.local_probes)), MAP * MAP)
    assert columns is not None
    for k in range(3):
        exact = J_exit[k::3, :, k]
        assert np.allclose(columns[k].toarray(), exact, rtol=0, atol=1e-10 * np.abs(exact).max())
        # the exit part is not the whole Jacobian: the entry's blur spreads each texel further
        assert np.abs(J[k::3, :, k] - exact).max() > 0.1 * np.abs(exact).max()


def _pcg_steps(A, b, inverse, rtol=1e-3):
    """Conjugate-gradient iterations on the Jacobi-scaled system until ||r|| <= rtol ||b||."""
    root = np.sqrt(np.diag(A))
    A, b = A / np.outer(root, root), b / root
    x, r = np.zeros_like(b), b.copy()
    z = inverse(r * root) * root
    p, gamma = z.copy(), r @ z
    for step in range(5000):
        if np.linalg.norm(r) <= rtol * np.linalg.norm(b):
            return step
        Ap = A @ p
        alpha = gamma / (p @ Ap)
        x, r = x + alpha * p, r - alpha * Ap
        z = inverse(r * root) * root
        gamma, previous = r @ z, gamma
        p = z + gamma / previous * p
    return 5000


@pytest.mark.parametrize("damping", [0.0, 0.01])
def test_the_step_converges_in_fewer_iterations(system, damping):
    """On the fitted texels of each channel (the mean free path held), the Gauss-Newton system
    (J^T J + damping diag, undamped as the fit runs and damped as Levenberg-Marquardt's) needs
    fewer conjugate-gradient iterations with the exit preconditioner than with the diagonal
    alone, and the preconditioned spectrum's middle half lies within [1/4, 4] (the module's
    argument: J^T J lies between J_exit^T J_exit and four times it)."""
    model, x, J, _ = system
    free = model.free.reshape(-1)
    r = np.asarray(model._raw(x, model.views))
    A_diag = np.stack([np.einsum("ij,ij->j", J[k::3, :, k], J[k::3, :, k]) for k in range(3)], -1)
    columns = texel_columns(np.asarray(model._local_columns(x, model.views, model.local_probes)), MAP * MAP)
    pre = LocalPreconditioner(columns, model.free, A_diag.reshape(model.free.shape + (3,)), np.ones(3), damping)
    plain = LocalPreconditioner(columns, model.free, A_diag.reshape(model.free.shape + (3,)), np.ones(3))
    for k in range(3):
        Jk = J[k::3][:, free, k]
        A = Jk.T @ Jk
        b = -Jk.T @ r[k::3]
        damped = A + damping * np.diag(np.diag(A))

        def inverse(v, factor=pre.factors[k]):
            return factor.solve(v)

        with_m = _pcg_steps(damped, b, inverse)
        diagonal = np.diag(damped)
        jacobi = _pcg_steps(damped, b, lambda v, diagonal=diagonal: v / diagonal)
        assert with_m < jacobi, (k, with_m, jacobi)
        spectrum = np.sort(np.real(np.linalg.eigvals(np.stack([plain.factors[k].solve(a.copy()) for a in A.T], 1))))
        quarter = len(spectrum) // 4
        assert 0.25 <= spectrum[quarter] and spectrum[-quarter] <= 4, (spectrum[quarter], spectrum[-quarter])
