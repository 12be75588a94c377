"""Linear stability of a steady motion: :func:`linearize`.

A steady motion of a system on $\\mathbb{R}^n$ is a motion with constant velocity $v^*$ along which
the equations do not change: $\\dot v = 0$ at $(q^*, v^*)$, and every coordinate that moves
($v^*_i \\ne 0$: a wheel's rotation, the position of the contact point) is one the equations do not
depend on (an ignorable coordinate). The upright bicycle or disk rolling straight at constant
speed is one; so is a rest point. Along it the linearized equations are constant:

$$\\frac{d}{dt}\\begin{pmatrix}\\delta q\\\\ \\delta v\\end{pmatrix} = J\\begin{pmatrix}\\delta q\\\\
\\delta v\\end{pmatrix}, \\qquad J = \\begin{pmatrix}0 & I\\\\ \\partial_q a & \\partial_v a\\end{pmatrix},$$

with $a(q, v)$ the constrained acceleration of the Lagrange–d'Alembert equations
(:func:`gnipy.equations.lagrange_dalembert_acceleration`), differentiated by JAX. Perturbations that
keep the constraints $\\mu(q)(v - Y(q)) = 0$ form the tangent space of the constraint manifold,
the null space of the constraints' derivative $K = \\partial(\\mu(v - Y))/\\partial(q, v)$; the flow
keeps the manifold, so $J$ maps that space into itself, and the stability of the motion is read
from the eigenvalues of $J$ restricted to it ($B^TJB$ with $B$ an orthonormal basis of
$\\ker K$, $2n - m$ of them). Each ignorable coordinate and each conserved quantity gives a zero
eigenvalue; a nonholonomic system that conserves energy has its other eigenvalues in pairs
$\\pm\\lambda$ (pure imaginary where the motion is stable, as the upright disk above its critical
speed: neutral, not asymptotic, stability).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..equations import lagrange_dalembert_acceleration
from ..errors import InputError

__all__ = ["Linearization", "linearize"]


@dataclass(frozen=True)
class Linearization:
    r"""The linearized equations about a steady motion (:func:`linearize`).

    Attributes:
        q, v: the steady motion's configuration and (constant) velocity.
        jacobian: $J$ (2n × 2n), in the state $(q, v)$.
        basis: an orthonormal basis $B$ (2n × k, k = 2n − m) of the perturbations that keep the
            constraints.
        reduced: $B^T J B$ (k × k), the linearized equations on the constraint manifold.
        eigenvalues: the k eigenvalues of `reduced`, largest real part first, those within
            `zero_tol` of 0 set to exactly 0 (and a real part within $10^{-6}$ `zero_tol` of 0,
            beside an imaginary part, to 0: round-off of $B^TJB$).
        zero_tol: the size below which an eigenvalue is read as zero, $10^{-4}\,\max(1, \|B^TJB\|_2)$:
            the zero eigenvalues of ignorable coordinates and conserved quantities come in Jordan
            blocks, which an eigenvalue computation resolves only to about
            $\varepsilon^{1/3}\|J\| \approx 6\cdot10^{-6}\|J\|$ (measured on the rolling disk: up to
            $3\cdot10^{-6}$ with $\|J\| \approx 40$). A genuine eigenvalue that small (a motion within
            about that of its critical speed) is read as zero too.
    """

    q: np.ndarray
    v: np.ndarray
    jacobian: np.ndarray
    basis: np.ndarray
    reduced: np.ndarray
    eigenvalues: np.ndarray
    zero_tol: float

    @property
    def zero_count(self) -> int:
        """How many eigenvalues are zero (ignorable coordinates, conserved quantities)."""
        return int(np.sum(self.eigenvalues == 0))

    @property
    def nonzero_eigenvalues(self) -> np.ndarray:
        """The eigenvalues that are not zero, largest real part first."""
        return self.eigenvalues[self.eigenvalues != 0]

    @property
    def growth_rate(self) -> float:
        r"""The largest real part of the eigenvalues (0 when all are zero or imaginary): > 0 for an
        unstable motion, whose perturbations grow like $e^{\text{growth rate}\cdot t}$."""
        return float(max(0.0, np.max(self.eigenvalues.real)))

    @property
    def stable(self) -> bool:
        """No eigenvalue with a positive real part (beyond `zero_tol`): stable to first order (for a
        conservative system, neutrally: its eigenvalues are then imaginary)."""
        return bool(np.all(self.eigenvalues.real <= self.zero_tol))


def linearize(system, q, v, *, tol: float = 1e-9) -> Linearization:
    """The linearized equations of `system` about the steady motion `(q, v)` (module docstring).

    Arguments:
        system: a System on $\\mathbb{R}^n$ without a force (a group system's linearization is not
            implemented).
        q, v: the steady motion: a configuration and a constant velocity on the constraints.
        tol: how closely the motion must be steady, relative to the size of the velocity: the
            constraints' residual and the acceleration, and the dependence of the equations on a
            coordinate that moves.

    Returns:
        A :class:`Linearization`, with the eigenvalues of the motion.

    Raises:
        InputError: when the system is not on $\\mathbb{R}^n$ or is forced, or when `(q, v)` is not
            a steady motion (off the constraints, accelerating, or moving along a coordinate that
            the equations depend on), naming what fails and by how much.
    """
    if system.group is not None:
        raise InputError(f"linearize: system {system.name!r} is on R^n x G; linearize takes systems on R^n")
    if system.is_forced:
        raise InputError(f"linearize: system {system.name!r} is forced; a steady motion is defined without inputs")
    n = system.n
    q = _vector(q, n, "q")
    v = _vector(v, n, "v")
    scale = 1.0 + float(np.max(np.abs(v)))

    def residual(state):
        qq, vv = state[:n], state[n:]
        r = system.mu(qq) @ vv
        return r - system.mu(qq) @ system.Y(qq) if system.is_affine else r

    def field(state):
        qq, vv = state[:n], state[n:]
        return jnp.concatenate([vv, lagrange_dalembert_acceleration(system, qq, vv)[0]])

    state = jnp.concatenate([q, v])
    off = float(jnp.max(jnp.abs(residual(state))))
    if off > tol * scale:
        raise InputError(f"linearize: (q, v) is not on the constraints: residual {off:.3g}")
    acceleration = np.asarray(field(state))[n:]
    if np.max(np.abs(acceleration)) > tol * scale:
        i = int(np.argmax(np.abs(acceleration)))
        raise InputError(f"linearize: (q, v) is not a steady motion: the velocity {system.velocities[i]!r} changes "
                         f"at rate {acceleration[i]:.3g}")
    J = np.asarray(jax.jacfwd(field)(state))
    moving = np.abs(np.asarray(v)) > tol * scale
    depends = np.max(np.abs(J[:, :n]), axis=0) > tol * scale * np.max(np.abs(J))
    coupled = moving & depends
    if np.any(coupled):
        names = ", ".join(repr(system.coordinates[i]) for i in np.flatnonzero(coupled))
        raise InputError(f"linearize: (q, v) is not a steady motion: the coordinates {names} move, and the equations "
                         f"depend on them (the linearized equations would change along the motion)")
    K = np.asarray(jax.jacfwd(residual)(state))
    _, s, Vt = np.linalg.svd(K)
    rank = int(np.sum(s > 1e-10 * max(1.0, s[0])))
    B = Vt[rank:].T
    reduced = B.T @ J @ B
    eigenvalues = np.linalg.eigvals(reduced)
    zero_tol = 1e-4 * max(1.0, float(np.linalg.norm(reduced, 2)))
    eigenvalues = np.where(np.abs(eigenvalues) <= zero_tol, 0.0, eigenvalues)
    # a real part or imaginary part at round-off next to a large other part is round-off too
    eigenvalues = np.where(np.abs(eigenvalues.real) <= zero_tol * 1e-6, 1j * eigenvalues.imag, eigenvalues)
    order = np.lexsort((eigenvalues.imag, -eigenvalues.real))
    return Linearization(q=np.asarray(q), v=np.asarray(v), jacobian=J, basis=B, reduced=reduced,
                         eigenvalues=eigenvalues[order], zero_tol=zero_tol)


def _vector(x, n: int, argument: str) -> jnp.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (n,):
        raise InputError(f"linearize: {argument} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"linearize: {argument} must be finite")
    return jnp.asarray(a)
