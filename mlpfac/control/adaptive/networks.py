"""NN_f and NN_G, the sigmoidal MLPs that estimate f and G of the error model, eqs. (8)-(27).

The weight vector follows (16)-(18)::

    z = [v_f, v_G]
    v_f = [w_1, w_2, w_3, s_f1, ..., s_fLf]            w_j (L_f,), s_fi (n_f,)
    v_G = [w_11, w_12, w_21, w_22, w_31, w_32, s_G1, ..., s_GLG]   w_jn (L_G,), s_Gi (n_G,)

so alpha = 3 L_f + L_f n_f + 6 L_G + L_G n_G (171 for L_f = 18, L_G = 1, n_f = 6, n_G = 3).
Inputs (8)-(9) carry a constant bias input: x_f = [c e, v_r, omega_r, 1], x_G = [c e1, c e2, 1],
where c is an input scale on the errors (1 in the paper). All functions accept leading batch
dimensions (``...``) on z and the inputs, so one call serves one run, a batch of runs or a set
of sigma points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mlpfac.exceptions import ConfigError

N_F = 6  # inputs of NN_f: e1, e2, e3, v_r, omega_r, bias
N_G = 3  # inputs of NN_G: e1, e2, bias


@dataclass(frozen=True)
class Networks:
    """Sizes and input conventions of NN_f and NN_G.

    ``error_scale`` multiplies the error inputs so they are O(1) like v_r and omega_r;
    ``residual`` makes NN_f estimate the increment f - e instead of f (then f_hat = e + NN_f).
    ``velocity_inputs`` appends the last command u_{k-1} to x_f (8): on a robot with actuator and
    inertia dynamics the velocity the robot has is a function of the commands before, and the one-step
    map is f(e, v_r, omega_r, u_{k-1}) + G u_k; n_f = 8.
    """

    L_f: int = 18  # hidden units of NN_f (10) (the paper: 18)
    L_G: int = 1  # hidden units of NN_G (11) (the paper: 1)
    error_scale: float = 20.0  # c: the error inputs of (8)-(9) are c e (the paper's inputs as printed: 1)
    residual: bool = False  # NN_f estimates f - e, so f_hat = e + NN_f
    velocity_inputs: bool = False  # NN_f also sees the last command u_{k-1} = (v, omega): the velocity state

    def __post_init__(self) -> None:
        for name in ("L_f", "L_G"):
            if getattr(self, name) < 1:
                raise ConfigError(name, f"a network needs at least 1 hidden unit, got {getattr(self, name)}")
        if not self.error_scale > 0:
            raise ConfigError("error_scale", f"must be positive, got {self.error_scale}")

    @property
    def n_f(self) -> int:
        """Inputs of NN_f: e1, e2, e3, v_r, omega_r, bias (and v, omega of u_{k-1} with ``velocity_inputs``)."""
        return N_F + 2 if self.velocity_inputs else N_F

    @property
    def alpha(self) -> int:
        """Total number of weights."""
        return 3 * self.L_f + self.L_f * self.n_f + 6 * self.L_G + self.L_G * N_G

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Views of z as W_f (..., 3, L_f), S_f (..., L_f, n_f), W_G (..., 3, 2, L_G), S_G (..., L_G, n_G)."""
        Lf, LG = self.L_f, self.L_G
        b = z.shape[:-1]
        i1 = 3 * Lf
        i2 = i1 + Lf * self.n_f
        i3 = i2 + 6 * LG
        return (
            z[..., :i1].reshape(*b, 3, Lf),
            z[..., i1:i2].reshape(*b, Lf, self.n_f),
            z[..., i2:i3].reshape(*b, 3, 2, LG),
            z[..., i3:].reshape(*b, LG, N_G),
        )

    def inputs(self, e: np.ndarray, v_r, omega_r, u_prev: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Eqs. (8)-(9): x_f (..., n_f) and x_G (..., 3) from e (..., 3) and the reference velocities
        (and the last command u_prev (..., 2) with ``velocity_inputs``)."""
        c = self.error_scale
        if np.ndim(e) == 1:  # one run: build the two short vectors directly
            ce1, ce2 = c * e[0], c * e[1]
            x_f = [ce1, ce2, c * e[2], v_r, omega_r, 1.0]
            if self.velocity_inputs:
                x_f += [u_prev[0], u_prev[1]]
            return np.array(x_f), np.array([ce1, ce2, 1.0])
        ce = c * np.asarray(e, dtype=float)
        one = np.ones(ce.shape[:-1])
        x_f = np.concatenate(
            [ce, np.stack([np.broadcast_to(v_r, one.shape), np.broadcast_to(omega_r, one.shape), one], -1)], -1
        )
        if self.velocity_inputs:
            x_f = np.concatenate([x_f, np.broadcast_to(u_prev, (*one.shape, 2))], -1)
        x_G = np.stack([ce[..., 0], ce[..., 1], one], -1)
        return x_f, x_G

    def forward(
        self, z: np.ndarray, x_f: np.ndarray, x_G: np.ndarray, e: np.ndarray, head: tuple | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Eqs. (10)-(15): f_hat (..., 3) and G_hat (..., 3, 2). ``e`` is used only when ``residual``.

        ``head``: the result of :meth:`head` for the same arguments, when the caller has it already.
        """
        W_f, W_G, phi_f, phi_G, f = head or self.head(z, x_f, x_G, e)
        return f, np.einsum("...jni,...i->...jn", W_G, phi_G)

    def head(self, z: np.ndarray, x_f: np.ndarray, x_G: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, ...]:
        """The hidden layers (10)-(11) and f_hat (14): W_f, W_G, phi_f (..., L_f), phi_G (..., L_G), f_hat (..., 3).

        The part of the networks that :meth:`forward`, :meth:`h_and_jacobian` and :meth:`jacobians`
        share; a controller that evaluates the networks at z_k for its law can pass the result to the
        next step's :meth:`h_and_jacobian`, which needs them at the same z_k and inputs.
        """
        W_f, S_f, W_G, S_G = self.split(z)
        phi_f = _sigmoid(np.einsum("...im,...m->...i", S_f, x_f))
        phi_G = _sigmoid(np.einsum("...im,...m->...i", S_G, x_G))
        f = np.einsum("...ji,...i->...j", W_f, phi_f)
        if self.residual:
            f = f + e
        return W_f, W_G, phi_f, phi_G, f

    def h(self, z: np.ndarray, x_f: np.ndarray, x_G: np.ndarray, e: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Eq. (26): h = f_hat + G_hat u, (..., 3)."""
        f, G = self.forward(z, x_f, x_G, e)
        return f + np.einsum("...jn,...n->...j", G, u)

    def h_and_jacobian(
        self,
        z: np.ndarray,
        x_f: np.ndarray,
        x_G: np.ndarray,
        e: np.ndarray,
        u: np.ndarray,
        head: tuple | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """h (..., 3) and its Jacobian nabla_h = [nabla_f, nabla_Gamma] (..., 3, alpha), eqs. (19)-(24), (27).

        ``head``: the result of :meth:`head` for the same z and inputs, when the caller has it already.
        """
        W_f, W_G, phi_f, phi_G, f = head or self.head(z, x_f, x_G, e)
        Lf, LG = self.L_f, self.L_G
        b = z.shape[:-1]
        Gu = np.einsum("...jni,...i,...n->...j", W_G, phi_G, u)
        i2 = 3 * Lf + Lf * self.n_f
        gamma = u[..., :, None] * phi_G[..., None, :]  # (..., 2, L_G): d (G u)_j / d w_jn = phi_G u_n (23)
        sigma = np.einsum("...jni,...n->...ji", W_G, u)  # sigma_{j,i} = sum_n w_{jn,i} u_n
        dphi_G = phi_G * (1.0 - phi_G)
        H = self._nabla_f(W_f, phi_f, x_f, b)  # (21)-(22), zero beyond
        for j in range(3):  # (23), diagonal in j: written where it is not zero
            H[..., j, i2 + 2 * LG * j : i2 + 2 * LG * (j + 1)] = gamma.reshape(*b, 2 * LG)
        # (24): d (G u)_j / d s_Gi = sigma_{j,i} phi_Gi (1 - phi_Gi) x_G
        H[..., :, i2 + 6 * LG :] = ((sigma * dphi_G[..., None, :])[..., :, :, None] * x_G[..., None, None, :]).reshape(
            *b, 3, LG * N_G
        )
        return f + Gu, H

    def jacobians(
        self, z: np.ndarray, x_f: np.ndarray, x_G: np.ndarray, e: np.ndarray, head: tuple | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """f_hat (..., 3), G_hat (..., 3, 2) and their Jacobians df/dz (..., 3, alpha), dG/dz (..., 3, 2, alpha).

        The same blocks as (19)-(24) without the input u: (21)-(22) for f; for G_jn, d G_jn / d w_jn = phi_G
        and d G_jn / d s_Gi = w_jn,i phi_Gi (1 - phi_Gi) x_G. Used by the cautious law, which needs the
        uncertainty of h1 = G_12, h2 = f_1 - e1, h5 = f_3 - e3 and of the input gains G_11, G_32.
        """
        W_f, W_G, phi_f, phi_G, f = head or self.head(z, x_f, x_G, e)
        Lf, LG = self.L_f, self.L_G
        b = z.shape[:-1]
        G = np.einsum("...jni,...i->...jn", W_G, phi_G)
        i2 = 3 * Lf + Lf * self.n_f
        df = self._nabla_f(W_f, phi_f, x_f, b)  # (21)-(22)
        dG = np.zeros((*b, 3, 2, self.alpha))
        eye6 = np.eye(6).reshape(3, 2, 3, 2)
        dG[..., i2 : i2 + 6 * LG] = (eye6[..., None] * phi_G[..., None, None, None, None, :]).reshape(*b, 3, 2, 6 * LG)
        dphi_G = phi_G * (1.0 - phi_G)
        dG[..., i2 + 6 * LG :] = (
            (W_G * dphi_G[..., None, None, :])[..., None] * x_G[..., None, None, None, :]
        ).reshape(*b, 3, 2, LG * N_G)
        return f, G, df, dG

    def _nabla_f(self, W_f: np.ndarray, phi_f: np.ndarray, x_f: np.ndarray, b: tuple) -> np.ndarray:
        """(..., 3, alpha): d f_j / dz, the blocks (21)-(22), and zeros for the weights of NN_G."""
        Lf = self.L_f
        out = np.zeros((*b, 3, self.alpha))
        for j in range(3):  # (21): d f_j / d w_j = phi_f, diagonal in j
            out[..., j, j * Lf : (j + 1) * Lf] = phi_f
        # (22): d f_j / d s_fi = w_{j,i} phi_fi (1 - phi_fi) x_f
        dphi_f = phi_f * (1.0 - phi_f)
        out[..., :, 3 * Lf : 3 * Lf + Lf * self.n_f] = (
            (W_f * dphi_f[..., None, :])[..., :, :, None] * x_f[..., None, None, :]
        ).reshape(*b, 3, Lf * self.n_f)
        return out

    def output_mask(self) -> np.ndarray:
        """True for the output-layer weights w_j (14) and w_jn (15), False for the hidden s_fi, s_Gi. (alpha,)"""
        m = np.zeros(self.alpha, dtype=bool)
        i2 = 3 * self.L_f + self.L_f * self.n_f
        m[: 3 * self.L_f] = True
        m[i2 : i2 + 6 * self.L_G] = True
        return m

    def labels(self) -> list[str]:
        """A name for each weight, ``network/layer/name_index``, in the order of z."""
        out = [f"NN_f/output/w{j + 1}_{i}" for j in range(3) for i in range(self.L_f)]
        out += [f"NN_f/hidden/s{i + 1}_{m}" for i in range(self.L_f) for m in range(self.n_f)]
        out += [f"NN_G/output/w{j + 1}{n + 1}_{i}" for j in range(3) for n in range(2) for i in range(self.L_G)]
        out += [f"NN_G/hidden/s{i + 1}_{m}" for i in range(self.L_G) for m in range(N_G)]
        return out


def _sigmoid(a: np.ndarray) -> np.ndarray:
    """Eqs. (10)-(11), written so that large |a| neither overflows nor loses precision."""
    from mlpfac.control.adaptive.kernels import sigmoids

    a = np.ascontiguousarray(a, dtype=float)
    out = np.empty_like(a)
    sigmoids(a.reshape(-1), out.reshape(-1))  # glibc's tanh, as the kernels: not numpy's SIMD loop
    return out
