"""The Suslov problem: a free rigid body whose angular velocity has no component along a body vector.

Pure rotation, $Q = SO(3)$ ($n = 0$, no coordinates $x$): velocities $v = \\Omega = (R^T\\dot R)^\\vee$
(body angular velocity). The inertia tensor $I$ (about the fixed point, in the body frame) need
not be diagonal:

$$l = \\tfrac12\\Omega^T I\\Omega, \\qquad \\langle a, \\Omega\\rangle = 0$$

for a fixed body vector $a$ (parameters `I11, I22, I33, I12, I13, I23`; `a1, a2, a3`, default
$a = e_3$). The system is reduced (paper §7): $l$ and $\\mu = a^T$ do not depend on $R$. The
Lagrange–d'Alembert–Poincaré equations are $I\\dot\\Omega = I\\Omega\\times\\Omega + \\lambda a$
($\\mathrm{ad}^*_\\Omega M = M\\times\\Omega$).

**Invariant.** The energy $E = \\tfrac12\\Omega^T I\\Omega$ (`energy`, a function `f(params, q, v)`).

**Exact solution** (:func:`exact`). The equations are covariant under a constant change of body
frame $\\Omega = Q\\Omega'$, $Q\\in SO(3)$ ($Q^T(u\\times w) = Q^Tu\\times Q^Tw$), so take the frame
$Q = (E_1, E_2, a/|a|)$ in which $a$ is the third axis and the 2×2 block of $I' = Q^TIQ$ orthogonal
to $a$ is diagonal, $I' = \\begin{pmatrix} I_1 & 0 & b_1\\\\ 0 & I_2 & b_2\\\\ b_1 & b_2 & I_3\\end{pmatrix}$
($E_1, E_2$ eigenvectors of that block). With $\\Omega'_3 = 0$ the first two components read

$$I_1\\dot\\Omega_1 = -\\Omega_2(b_1\\Omega_1 + b_2\\Omega_2), \\qquad
  I_2\\dot\\Omega_2 = \\Omega_1(b_1\\Omega_1 + b_2\\Omega_2)$$

(the third fixes λ). They conserve $E = \\tfrac12(I_1\\Omega_1^2 + I_2\\Omega_2^2)$; with
$\\sqrt{I_1}\\Omega_1 = \\sqrt{2E}\\cos\\varphi$, $\\sqrt{I_2}\\Omega_2 = \\sqrt{2E}\\sin\\varphi$ both become

$$\\dot\\varphi = \\frac{b_1\\Omega_1 + b_2\\Omega_2}{\\sqrt{I_1I_2}} = A\\cos(\\varphi - \\varphi^*), \\qquad
A = \\frac{\\sqrt{2E}\\,|\\beta|}{\\sqrt{I_1I_2}}, \\quad
\\beta = \\Bigl(\\frac{b_1}{\\sqrt{I_1}}, \\frac{b_2}{\\sqrt{I_2}}\\Bigr), \\quad
\\varphi^* = \\operatorname{atan2}(\\beta_2, \\beta_1).$$

With $\\psi = \\varphi - \\varphi^*$, $\\sec\\psi\\,d\\psi = A\\,dt$ integrates to
$\\tan(\\psi/2 + \\pi/4) = \\tan(\\psi_0/2 + \\pi/4)\\,e^{At}$, i.e. $\\psi = \\operatorname{gd}(At + c_0)$ with
the Gudermannian $\\operatorname{gd}(s) = 2\\arctan e^s - \\pi/2$ and $c_0 = \\operatorname{gd}^{-1}(\\psi_0)$.
Written as $\\psi(t) = 2\\arctan\\bigl(\\tan(\\psi_0/2 + \\pi/4)e^{At}\\bigr) - \\pi/2$ with $\\psi_0$ taken in
$(-3\\pi/2, \\pi/2]$ it covers every initial angle, including the equilibria $\\psi_0 = \\pm\\pi/2$
(steady rotations about the two axes $\\cos\\psi = 0$ of the plane $a^\\perp$). Every other solution
is a heteroclinic orbit from $\\psi = -\\pi/2$ to $\\psi = \\pi/2$ (for $A > 0$): the body ends in
steady rotation. When $b_1 = b_2 = 0$, $\\Omega$ is constant. The attitude $R$ has no closed form
here; :func:`exact` returns $\\Omega$ (and an empty $q$).

Defaults: $I = \\begin{pmatrix} 2 & 0.3 & 0.6\\\\ 0.3 & 3 & -0.5\\\\ 0.6 & -0.5 & 4\\end{pmatrix}$,
$a = e_3$, $R_0$ the identity, $\\Omega_0 = w - \\frac{\\langle a, w\\rangle}{|a|^2}a$ with
$w = (1, 0.5, 0.3)$: $\\Omega_0 = (1, 0.5, 0)$ for $a = e_3$.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..lie_groups import SO3
from ..system import System
from ..registry import ModelSpec, register

__all__ = ["MODEL", "adapted_frame", "exact", "inertia_tensor"]

VELOCITIES = ("Omega1", "Omega2", "Omega3")
W0 = (1.0, 0.5, 0.3)


def inertia_tensor(p):
    """The symmetric inertia tensor from the parameters (a NumPy array)."""
    return np.array(
        [[p["I11"], p["I12"], p["I13"]], [p["I12"], p["I22"], p["I23"]], [p["I13"], p["I23"], p["I33"]]],
        dtype=np.float64,
    )


def _a(p):
    return np.array([p["a1"], p["a2"], p["a3"]], dtype=np.float64)


def _inertia_tensor(p):
    """:func:`inertia_tensor` traceable (jnp), for the System's functions."""
    return jnp.asarray(
        [[p["I11"], p["I12"], p["I13"]], [p["I12"], p["I22"], p["I23"]], [p["I13"], p["I23"], p["I33"]]]
    )


def _lagrangian(x, v, p):
    return 0.5 * v @ _inertia_tensor(p) @ v


def _constraints(x, p):
    return jnp.asarray([p["a1"], p["a2"], p["a3"]])[None, :]


def _energy(p, q, v):
    v = jnp.asarray(v)
    return 0.5 * v @ jnp.asarray(inertia_tensor(p)) @ v


def _default_ic(p):
    a, w = _a(p), np.asarray(W0)
    Om = w - (a @ w) / (a @ a) * a
    return (), tuple(float(x) for x in Om)


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        n=0,
        group=SO3(),
        coordinates=(),
        velocities=VELOCITIES,
        name="suslov",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


def adapted_frame(p):
    """The body frame $Q = (E_1, E_2, a/|a|) \\in SO(3)$ of the exact solution and $I' = Q^TIQ$.

    Returns `(Q, I1, I2, b1, b2)`: the diagonal of the block of $I'$ orthogonal to $a$ and the
    couplings $b_i = I'_{i3}$.
    """
    I, a = inertia_tensor(p), _a(p)
    n = a / np.linalg.norm(a)
    # an orthonormal basis (e, f) of the plane a^⊥ from the SVD of the projector onto it
    u, _, _ = np.linalg.svd(np.eye(3) - np.outer(n, n))
    B = u[:, :2]
    _lam, U = np.linalg.eigh(B.T @ I @ B)
    E = B @ U
    Q = np.column_stack([E[:, 0], E[:, 1], n])
    if np.linalg.det(Q) < 0:
        Q[:, 1] = -Q[:, 1]
    Ip = Q.T @ I @ Q
    return Q, Ip[0, 0], Ip[1, 1], Ip[0, 2], Ip[1, 2]


def exact(p, q0, v0, t):
    """Exact body angular velocity $\\Omega(t)$ (see the module docstring), from t = 0.

    Arguments:
        p: the parameters.
        q0: ignored (there are no coordinates x).
        v0: $\\Omega_0$ on the constraint $\\langle a, \\Omega_0\\rangle = 0$.
        t: times, array (T,).

    Returns:
        `(q, v)`: an empty (T, 0) array and $\\Omega$, (T, 3).
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    Q, I1, I2, b1, b2 = adapted_frame(p)
    W0p = Q.T @ np.asarray(v0, dtype=np.float64)
    E = 0.5 * (I1 * W0p[0] ** 2 + I2 * W0p[1] ** 2)
    q = np.zeros((t.size, 0))
    if E == 0.0:
        return q, np.zeros((t.size, 3))
    s1, s2 = np.sqrt(I1), np.sqrt(I2)
    phi0 = np.arctan2(s2 * W0p[1], s1 * W0p[0])
    beta = np.array([b1 / s1, b2 / s2])
    A = np.sqrt(2 * E) * np.linalg.norm(beta) / (s1 * s2)
    phi_star = np.arctan2(beta[1], beta[0])
    psi0 = np.mod(phi0 - phi_star + 1.5 * np.pi, 2 * np.pi) - 1.5 * np.pi  # in [-3π/2, π/2)
    psi = 2 * np.arctan(np.tan(0.5 * psi0 + 0.25 * np.pi) * np.exp(A * t)) - 0.5 * np.pi
    phi = phi_star + psi
    Wp = np.sqrt(2 * E) * np.stack([np.cos(phi) / s1, np.sin(phi) / s2, np.zeros_like(phi)], axis=-1)
    return q, Wp @ Q.T


_DEFAULTS = {
    "I11": 2.0, "I22": 3.0, "I33": 4.0, "I12": 0.3, "I13": 0.6, "I23": -0.5,
    "a1": 0.0, "a2": 0.0, "a3": 1.0,
}

MODEL = register(
    ModelSpec(
        name="suslov",
        description="Suslov problem: rigid body with non-diagonal inertia, <a, Omega> = 0 for a body vector a, "
        "on SO(3)",
        build=_build,
        params=_DEFAULTS,
        coordinates=(),
        q0=(),
        v0=_default_ic(_DEFAULTS)[1],
        default_ic=_default_ic,
        exact=exact,
        invariants={"energy": _energy},
        notes=__doc__,
        positive=('I11', 'I22', 'I33'),
    )
)
