"""The GNI step written the way a researcher writes it: NumPy, hand-derived formulas, SciPy's `root`.

This is the *baseline* of the benchmark: the same discrete equations as gnipy's GNI (gnipy's docs,
conventions page; src/gnipy/integrators/gni.py), but written out by hand for each model, with one
`scipy.optimize.root(..., method="hybr", tol=1e-12)` per step and a Python `for` loop over steps.
It is deliberately plain (readable, not optimized): no JAX, no compilation, no vectorization.
Everything below is hand-derived because that is what a researcher without gnipy has to do:
derive the gradients of the discrete Lagrangian, the retraction's tangent map and the projectors
for each new model.

One GNI step from $(b_k, p^+_k)$ (gnipy's docs, conventions page, "Projectors and the reflection
(Comb)" and "What is reported at a node"):

1. reflect (Comb): $p^-_k = p^+_k - 2Q^*(p^+_k - \\Pi(b_k))$, $Q^* = \\mu^T C^{-1}\\mu\\mathbb{G}^{-1}$,
   $C = \\mu\\mathbb{G}^{-1}\\mu^T$;
2. solve $FL^-(b_k, z) = p^-_k$ for $z$ ($z = q_{k+1}$ on $\\mathbb{R}^n$;
   $z = (x_{k+1}, \\sigma_k)$ on $\\mathbb{R}^n\\times SO(3)$) with `scipy.optimize.root`, from the
   first guess $z_0 = (x_k + h\\dot{\\bar x}_k, h\\bar\\xi_k)$ that gnipy uses too;
3. $R_{k+1} = R_k\\,\\mathrm{cay}(\\sigma_k)$ ($\\mathrm{cay}(\\sigma_k)\\,R_k$ for the rolling ball, whose ω is the
   space angular velocity, as in gnipy's model) and $p^+_{k+1} = FL^+(b_k, z)$.

The reported node values are $\\bar p_k = p^+_k - Q^*(p^+_k - \\Pi)$ and $\\bar v_k = \\mathbb{G}^{-1}\\bar p_k$
(what `gnipy.Solution.p` and `.v` hold). The start is $p^+_0 = \\mathbb{G}v_0$.

On $\\mathbb{R}^n\\times SO(3)$ the discrete Legendre transforms are ((RedLegTr), §9)

    FL⁻ = ( −∂l_d/∂x_k ,    dcay⁻¹_σᵀ ∂l_d/∂σ − ∇ᴸ_{R_k} l_d ),
    FL⁺ = (  ∂l_d/∂x_{k+1}, dcay⁻¹_{−σ}ᵀ ∂l_d/∂σ ),

with the Cayley closed forms $\\mathrm{cay}(\\sigma) = I + \\frac{4}{4+|\\sigma|^2}(\\hat\\sigma + \\hat\\sigma^2/2)$
and $\\mathrm{dcay}^{-1}_\\sigma = I - \\hat\\sigma/2 + \\sigma\\sigma^T/4$ (paper, Appendix).

Cases (parameters and initial conditions copied from the model files, so that this module does not
import gnipy):

- :class:`RollingBallEx2`: the paper's rolling ball, example 2 (§7.4, Fig. 3), "gni-trapezoid";
- :class:`ContactOscillator`: McLachlan–Perlmutter's contact oscillator, "rattle" (the paper's
  explicit nonholonomic RATTLE) and "gni-midpoint";
- :class:`ChaplyginSphere`: the physical Chaplygin sphere (constraints depend on R: the Lie groupoid
  case of §9), "gni-trapezoid".

Each case has `initial_state()`, `step(state, h)`, `observe(state)` and
`run(steps, h, save_all=False)`; :func:`run` and :func:`get_case` look cases up by name.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from scipy.optimize import root

__all__ = [
    "CASES",
    "ChaplyginSphere",
    "ContactOscillator",
    "RollingBallEx2",
    "cayley",
    "dcay_inv",
    "get_case",
    "hat",
    "reflect_and_report",
    "run",
]

ROOT_TOL = 1e-12  # the `tol` of scipy.optimize.root (hybr: relative tolerance on z)
RESIDUAL_ACCEPT = 1e-10  # a reported failure with a residual this small (relative) is converged


# ---------------------------------------------------------------------------------------------
# SO(3) and the Cayley retraction: closed forms, written out by hand (paper, Appendix)
# ---------------------------------------------------------------------------------------------


def hat(w):
    """The skew matrix $\\hat w$ with $\\hat w u = w\\times u$."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def cayley(s):
    """$\\mathrm{cay}(\\sigma) = I + \\frac{4}{4 + |\\sigma|^2}(\\hat\\sigma + \\hat\\sigma^2/2)$."""
    S = hat(s)
    return np.eye(3) + (4.0 / (4.0 + s @ s)) * (S + 0.5 * S @ S)


def dcay_inv(s):
    """$\\mathrm{dcay}^{-1}_\\sigma = I - \\hat\\sigma/2 + \\sigma\\sigma^T/4$ (right-trivialized, as a 3×3 matrix)."""
    return np.eye(3) - 0.5 * hat(s) + 0.25 * np.outer(s, s)


# ---------------------------------------------------------------------------------------------
# Projectors and the reflection (Comb): plain dense linear algebra
# ---------------------------------------------------------------------------------------------


def reflect_and_report(G, mu, Pi, p_plus):
    """The GNI's node momenta: `(p_minus, p_bar, v_bar)`.

    $Q^*(p^+ - \\Pi) = \\mu^T C^{-1}\\mu\\mathbb{G}^{-1}(p^+ - \\Pi)$; the reflection (Comb)
    $p^- = p^+ - 2Q^*(p^+ - \\Pi)$, the reported $\\bar p = p^+ - Q^*(p^+ - \\Pi)$ and
    $\\bar v = \\mathbb{G}^{-1}\\bar p$.
    """
    Ginv_muT = np.linalg.solve(G, mu.T)
    C = mu @ Ginv_muT
    q_star = mu.T @ np.linalg.solve(C, Ginv_muT.T @ (p_plus - Pi))  # G symmetric: μG⁻¹ = (G⁻¹μᵀ)ᵀ
    p_bar = p_plus - q_star
    return p_plus - 2.0 * q_star, p_bar, np.linalg.solve(G, p_bar)


def _root(residual, jacobian, guess, scale=1.0):
    """One call of `scipy.optimize.root(method="hybr", tol=1e-12)`; raises if it fails.

    `jacobian` is the hand-derived Jacobian, or None to let MINPACK difference the residual.
    MINPACK often reports failure (status 5, "not making good progress") when the first guess is
    already so good that the residual sits at its round-off floor: its convergence test is on the
    trust-region radius, which stays large while the steps are tiny (most steps at h = 0.001, a
    few at h = 0.01). Such a result is accepted when max|F| <= 1e-10 max(1, `scale`), `scale`
    being the size of the right-hand side p⁻.
    Returns `(z, nfev)`.
    """
    sol = root(residual, guess, jac=jacobian, method="hybr", tol=ROOT_TOL)
    if not sol.success and not np.max(np.abs(sol.fun)) <= RESIDUAL_ACCEPT * max(1.0, scale):
        raise RuntimeError(f"scipy.optimize.root failed: {sol.message} (residual {np.max(np.abs(sol.fun)):.3e})")
    return sol.x, sol.nfev


def _run(case, steps, h, save_all):
    """The Python loop over steps shared by all cases; returns the final (or every) node."""
    state = case.initial_state()
    nodes = [case.observe(state)] if save_all else None
    nfev = 0
    for _ in range(int(steps)):
        state, n = case.step(state, h)
        nfev += n
        if save_all:
            nodes.append(case.observe(state))
    if save_all:
        out = {key: (None if nodes[0][key] is None else np.stack([nd[key] for nd in nodes])) for key in nodes[0]}
        out["t"] = h * np.arange(int(steps) + 1)
    else:
        out = case.observe(state)
        out["t"] = h * int(steps)
    out["nfev"] = nfev
    return out


# ---------------------------------------------------------------------------------------------
# A ball on a table, R^2 x SO(3), trapezoid l_d (shared by the rolling ball and the Chaplygin sphere)
# ---------------------------------------------------------------------------------------------


class _BallTrapezoid:
    """GNI with the trapezoid $l_d$ and the Cayley retraction for a ball on $\\mathbb{R}^2\\times SO(3)$.

    Both balls have $l = \\tfrac12 m|\\dot x|^2 + \\tfrac12\\Omega^T I\\Omega$ (no potential, no
    R-dependence of $l$), so $\\mathbb{G} = \\mathrm{diag}(m, m, I_1, I_2, I_3)$ and, with
    $\\Delta = (x_{k+1} - x_k)/h$, the trapezoid $l_d = \\tfrac h2(l(b_k, v) + l(b_{k+1}, v))$ is
    simply $l_d = \\frac{m}{2h}|x_{k+1} - x_k|^2 + \\frac{1}{2h}\\sigma^T I\\sigma$. By hand:

        ∂l_d/∂x_k = −mΔ,  ∂l_d/∂x_{k+1} = mΔ,  ∂l_d/∂σ = Iσ/h,  ∇ᴸ_{R_k} l_d = 0

    (the last because $l$ does not see $R$; for the Chaplygin sphere only μ does). The subclasses
    give the constraints $\\mu(x, R)$ and the affine part $Y(x, R)$.
    """

    name = "ball"
    method = "gni-trapezoid"
    #: True when the angular velocity is the space one: R_{k+1} = cay(σ_k) R_k (else R_k cay(σ_k)).
    space_angular_velocity = False

    def __init__(self, params, q0, v0, R0=None, *, jac=True):
        self.params = {k: float(v) for k, v in params.items()}
        self.m = self.params["m"]
        self.r = self.params["r"]
        self.inertia = np.array([self.params["I1"], self.params["I2"], self.params["I3"]])
        self.G = np.diag([self.m, self.m, *self.inertia])
        self.q0 = np.asarray(q0, dtype=float)
        self.v0 = np.asarray(v0, dtype=float)
        self.R0 = np.eye(3) if R0 is None else np.asarray(R0, dtype=float).reshape(3, 3)
        self.jac = bool(jac)

    # the model: constraints μ(b)(v − Y(b)) = 0
    def mu(self, x, R):
        """The constraint one-forms μ(x, R), shape (2, 5)."""
        raise NotImplementedError

    def Y(self, x, R):
        """The affine part Y(x, R): the table's velocity under the contact point."""
        W = self.params["Omega"]
        return np.array([-W * x[1], W * x[0], 0.0, 0.0, 0.0])

    def Pi(self, x, R):
        """$\\Pi = \\mathbb{G}Y$."""
        return self.G @ self.Y(x, R)

    # discrete Legendre transforms, by hand (see the class docstring)
    def legendre_minus(self, x0, R0, z, h):
        """$FL^- = (-\\partial l_d/\\partial x_k,\\ \\mathrm{dcay}^{-1}_\\sigma{}^T\\,\\partial l_d/\\partial\\sigma - \\nabla^L_{R_k}l_d)$."""
        x1, s = z[:2], z[2:]
        dld_dx0 = -self.m * (x1 - x0) / h
        dld_ds = self.inertia * s / h
        grad_R = np.zeros(3)  # l_d does not depend on R_k at fixed σ
        return np.concatenate([-dld_dx0, dcay_inv(s).T @ dld_ds - grad_R])

    def legendre_plus(self, x0, R0, z, h):
        """$FL^+ = (\\partial l_d/\\partial x_{k+1},\\ \\mathrm{dcay}^{-1}_{-\\sigma}{}^T\\,\\partial l_d/\\partial\\sigma)$."""
        x1, s = z[:2], z[2:]
        return np.concatenate([self.m * (x1 - x0) / h, dcay_inv(-s).T @ (self.inertia * s / h)])

    def legendre_minus_jacobian(self, z, h):
        """$\\partial FL^-/\\partial z$ by hand. With $M = I\\sigma$ and
        $\\mathrm{dcay}^{-1}_\\sigma{}^T M = M + \\tfrac12\\sigma\\times M + \\tfrac14\\sigma(\\sigma^TM)$:
        $\\partial/\\partial\\sigma = I + \\tfrac12(\\hat\\sigma I - \\widehat{I\\sigma}) + \\tfrac14((\\sigma^TI\\sigma)E + 2\\sigma\\sigma^TI)$."""
        s = z[2:]
        Isig = self.inertia * s
        Imat = np.diag(self.inertia)
        Js = Imat + 0.5 * (hat(s) @ Imat - hat(Isig)) + 0.25 * ((s @ Isig) * np.eye(3) + 2.0 * np.outer(s, Isig))
        J = np.zeros((5, 5))
        J[:2, :2] = self.m / h * np.eye(2)
        J[2:, 2:] = Js / h
        return J

    # the GNI
    def initial_state(self):
        """$(x_0, R_0, p^+_0 = \\mathbb{G}v_0)$."""
        return self.q0.copy(), self.R0.copy(), self.G @ self.v0

    def step(self, state, h):
        """One GNI step $(x_k, R_k, p^+_k) \\mapsto (x_{k+1}, R_{k+1}, p^+_{k+1})$; returns `(state, nfev)`."""
        x, R, p_plus = state
        p_minus, _, v_bar = reflect_and_report(self.G, self.mu(x, R), self.Pi(x, R), p_plus)

        def residual(z):
            return self.legendre_minus(x, R, z, h) - p_minus

        jacobian = (lambda z: self.legendre_minus_jacobian(z, h)) if self.jac else None
        guess = np.concatenate([x + h * v_bar[:2], h * v_bar[2:]])
        z, nfev = _root(residual, jacobian, guess, np.max(np.abs(p_minus)))
        g = cayley(z[2:])
        x1, R1 = z[:2], (g @ R if self.space_angular_velocity else R @ g)
        return (x1, R1, self.legendre_plus(x, R, z, h)), nfev

    def observe(self, state):
        """The reported node: `dict(q=x, v=v̄, p=p̄, R=R)`."""
        x, R, p_plus = state
        _, p_bar, v_bar = reflect_and_report(self.G, self.mu(x, R), self.Pi(x, R), p_plus)
        return {"q": x, "v": v_bar, "p": p_bar, "R": R}

    def run(self, steps, h, save_all=False):
        """Integrate `steps` steps of size `h` from the initial condition.

        Returns:
            `dict(q, v, p, R, t, nfev)`: the final node (or every node, stacked, with
            `save_all=True`); `nfev` counts residual evaluations in all root solves.
        """
        return _run(self, steps, h, save_all)


class RollingBallEx2(_BallTrapezoid):
    """The paper's rolling ball, example 2 (§7.4, Fig. 3; gnipy's `rolling_ball.example_2()`).

    Reduced on $\\mathbb{R}^2\\times SO(3)$: $\\mu = [[1, 0, 0, -r, 0], [0, 1, r, 0, 0]]$ (the paper's model;
    ω the space angular velocity, so $R_{k+1} = \\mathrm{cay}(\\sigma_k)R_k$),
    $Y = (-\\Omega y, \\Omega x, 0, 0, 0)$; $m = 3$, $r = 1$,
    $I = (1, 1.1, 1.2)$, $\\Omega = 0.2$; $q_0 = (1, 0)$, $v_0 = (0, 0.4, -0.2, 0, 0.4)$, $R_0 = I$.
    Method "gni-trapezoid".

    Arguments:
        params, q0, v0, R0: override the example's values.
        jac: pass the hand-derived Jacobian to `root` (False: MINPACK's finite differences).
    """

    name = "rolling_ball_ex2"
    space_angular_velocity = True
    PARAMS: ClassVar[dict[str, float]] = {"m": 3.0, "r": 1.0, "I1": 1.0, "I2": 1.1, "I3": 1.2, "Omega": 0.2}
    Q0 = (1.0, 0.0)
    V0 = (0.0, 0.4, -0.2, 0.0, 0.4)  # (ẋ, ẏ) = (rω₂ − Ωy, Ωx − rω₁) from ω₀ = (−0.2, 0, 0.4)

    def __init__(self, params=None, q0=None, v0=None, R0=None, *, jac=True):
        super().__init__(
            self.PARAMS if params is None else params,
            self.Q0 if q0 is None else q0,
            self.V0 if v0 is None else v0,
            R0,
            jac=jac,
        )

    def mu(self, x, R):
        """(Cona), (Conb): $\\dot x - r\\omega_2 = \\ldots$, $\\dot y + r\\omega_1 = \\ldots$ (constant)."""
        r = self.r
        return np.array([[1.0, 0.0, 0.0, -r, 0.0], [0.0, 1.0, r, 0.0, 0.0]])


class ChaplyginSphere(_BallTrapezoid):
    """The physical Chaplygin sphere (gnipy's model "chaplygin-sphere"), Lie groupoid case.

    The rolling constraints use the space angular velocity $\\omega = R\\Omega$:
    $\\mu(R) = [[1, 0, -rR_{2,:}], [0, 1, rR_{1,:}]]$, $Y = (-\\Omega_t y, \\Omega_t x, 0, 0, 0)$.
    Defaults: $m = r = 1$, $I = (0.3, 0.4, 0.5)$, $\\Omega_t = 0$; $q_0 = (0, 0)$, $R_0 = I$,
    $v_0 = (0.5, -1, 1, 0.5, 2)$. Method "gni-trapezoid". The step is the same as the rolling
    ball's except that the reflection uses $\\mu(R_k)$ ($l$ does not depend on R, so
    $\\nabla^L_{R_k}l_d = 0$).

    Arguments:
        params, q0, v0, R0: override the defaults.
        jac: pass the hand-derived Jacobian to `root` (False: MINPACK's finite differences).
    """

    name = "chaplygin_sphere"
    PARAMS: ClassVar[dict[str, float]] = {"m": 1.0, "r": 1.0, "I1": 0.3, "I2": 0.4, "I3": 0.5, "Omega": 0.0}
    Q0 = (0.0, 0.0)
    V0 = (0.5, -1.0, 1.0, 0.5, 2.0)

    def __init__(self, params=None, q0=None, v0=None, R0=None, *, jac=True):
        super().__init__(
            self.PARAMS if params is None else params,
            self.Q0 if q0 is None else q0,
            self.V0 if v0 is None else v0,
            R0,
            jac=jac,
        )

    def mu(self, x, R):
        """$\\dot x - r\\omega_2 + \\Omega_t y = 0$, $\\dot y + r\\omega_1 - \\Omega_t x = 0$ with $\\omega = R\\Omega$."""
        r = self.r
        return np.array([[1.0, 0.0, *(-r * R[1])], [0.0, 1.0, *(r * R[0])]])


# ---------------------------------------------------------------------------------------------
# The contact oscillator on R^3: explicit RATTLE and the GNI with the midpoint l_d
# ---------------------------------------------------------------------------------------------


class ContactOscillator:
    """McLachlan–Perlmutter's contact oscillator (gnipy's model "contact-oscillator").

    $l = \\tfrac12|\\dot q|^2 - V(q)$, $V = \\tfrac12(|q|^2 + \\varepsilon x^2z^2)$ on $q = (x, y, z)$,
    constraint $\\dot x + y\\dot z = 0$: $\\mu(q) = (1, 0, y)$, $\\mathbb{G} = I$, no affine part.
    Defaults $\\varepsilon = 0.3$, $q_0 = (1, 1, 1)$, $v_0 = (-1, 1, 1)$.

    Methods:
        "rattle": the paper's explicit nonholonomic RATTLE (kick–drift–kick on
            $(q, \\tilde p, \\tilde\\lambda)$, one scalar linear solve for $\\tilde\\lambda_{k+1}$; no root
            finder is needed), as in gnipy's `paper_schemes.rattle_map`;
        "gni-midpoint": the GNI with $l_d = h\\,l((q_k + q_{k+1})/2, (q_{k+1} - q_k)/h)$, one
            `scipy.optimize.root` per step.

    Arguments:
        method: "rattle" or "gni-midpoint".
        params, q0, v0: override the defaults.
        jac: (gni-midpoint) pass the hand-derived Jacobian to `root`.
    """

    name = "contact_oscillator"
    METHODS = ("rattle", "gni-midpoint")
    PARAMS: ClassVar[dict[str, float]] = {"epsilon": 0.3}
    Q0 = (1.0, 1.0, 1.0)
    V0 = (-1.0, 1.0, 1.0)

    def __init__(self, method="rattle", params=None, q0=None, v0=None, *, jac=True):
        if method not in self.METHODS:
            raise ValueError(f"method: expected one of {self.METHODS}, got {method!r}")
        self.method = method
        self.params = {k: float(v) for k, v in (self.PARAMS if params is None else params).items()}
        self.eps = self.params["epsilon"]
        self.q0 = np.asarray(self.Q0 if q0 is None else q0, dtype=float)
        self.v0 = np.asarray(self.V0 if v0 is None else v0, dtype=float)
        self.G = np.eye(3)
        self.jac = bool(jac)

    # the model, by hand
    def mu(self, q):
        """$\\mu(q) = (1, 0, y)$, shape (1, 3)."""
        return np.array([[1.0, 0.0, q[1]]])

    def grad_V(self, q):
        """$\\nabla V = (x + \\varepsilon xz^2,\\ y,\\ z + \\varepsilon x^2z)$."""
        x, y, z = q
        return np.array([x + self.eps * x * z * z, y, z + self.eps * x * x * z])

    def hess_V(self, q):
        """$\\nabla^2 V$ (for the Jacobian of the midpoint step)."""
        x, _, z = q
        e = self.eps
        return np.array([[1.0 + e * z * z, 0.0, 2 * e * x * z], [0.0, 1.0, 0.0], [2 * e * x * z, 0.0, 1.0 + e * x * x]])

    # midpoint l_d = h(½|Δ|² − V(q_mid)): ∂l_d/∂q_k = −Δ − (h/2)∇V(q_mid), ∂l_d/∂q_{k+1} = Δ − (h/2)∇V(q_mid)
    def legendre_minus(self, q0, q1, h):
        """$FL^- = -\\partial l_d/\\partial q_k = \\Delta + \\tfrac h2\\nabla V(q_{k+1/2})$ (midpoint $l_d$)."""
        return (q1 - q0) / h + 0.5 * h * self.grad_V(0.5 * (q0 + q1))

    def legendre_plus(self, q0, q1, h):
        """$FL^+ = \\partial l_d/\\partial q_{k+1} = \\Delta - \\tfrac h2\\nabla V(q_{k+1/2})$."""
        return (q1 - q0) / h - 0.5 * h * self.grad_V(0.5 * (q0 + q1))

    def legendre_minus_jacobian(self, q0, q1, h):
        """$\\partial FL^-/\\partial q_{k+1} = I/h + \\tfrac h4\\nabla^2V(q_{k+1/2})$."""
        return np.eye(3) / h + 0.25 * h * self.hess_V(0.5 * (q0 + q1))

    # states: GNI (q, p⁺); RATTLE (q, p̃, λ̃)
    def initial_state(self):
        """GNI: $(q_0, p^+_0 = v_0)$. RATTLE: $(q_0, \\tilde p_0, \\tilde\\lambda_0)$ read from the
        GNI start as gnipy's `tilde_state_from_gni` does ($\\tilde p_0 = \\bar p_0$,
        $\\tilde\\lambda_0 = (2/h)C^{-1}\\mu p^+_0 = 0$ for $v_0$ on the constraints)."""
        p_plus = self.G @ self.v0
        if self.method == "gni-midpoint":
            return self.q0.copy(), p_plus
        _, p_bar, _ = reflect_and_report(self.G, self.mu(self.q0), np.zeros(3), p_plus)
        return self.q0.copy(), p_bar, np.zeros(1)

    def step(self, state, h):
        """One step of the chosen method; returns `(state, nfev)` (nfev = 0 for RATTLE)."""
        if self.method == "rattle":
            return self._rattle_step(state, h), 0
        return self._gni_midpoint_step(state, h)

    def _rattle_step(self, state, h):
        """Nonholonomic RATTLE ((nonholonomicRATTLE); M = I, Π = 0):

        p_{k+1/2} = p̃_k − (h/2)(∇V(q_k) + μ(q_k)ᵀλ̃_k);  q_{k+1} = q_k + h p_{k+1/2};
        p̃_{k+1} = p_{k+1/2} − (h/2)(∇V(q_{k+1}) + μ(q_{k+1})ᵀλ̃_{k+1})  with  μ(q_{k+1}) p̃_{k+1} = 0,
        i.e. (h/2) C λ̃_{k+1} = μ(q_{k+1})(p_{k+1/2} − (h/2)∇V(q_{k+1})).
        """
        q, p, lam = state
        p_half = p - 0.5 * h * (self.grad_V(q) + self.mu(q).T @ lam)
        q1 = q + h * p_half
        mu1, dV1 = self.mu(q1), self.grad_V(q1)
        C1 = mu1 @ mu1.T
        lam1 = (2.0 / h) * np.linalg.solve(C1, mu1 @ (p_half - 0.5 * h * dV1))
        p1 = p_half - 0.5 * h * (dV1 + mu1.T @ lam1)
        return q1, p1, lam1

    def _gni_midpoint_step(self, state, h):
        """The GNI step with the midpoint $l_d$ (one `scipy.optimize.root` for $q_{k+1}$)."""
        q, p_plus = state
        p_minus, _, v_bar = reflect_and_report(self.G, self.mu(q), np.zeros(3), p_plus)

        def residual(q1):
            return self.legendre_minus(q, q1, h) - p_minus

        jacobian = (lambda q1: self.legendre_minus_jacobian(q, q1, h)) if self.jac else None
        q1, nfev = _root(residual, jacobian, q + h * v_bar, np.max(np.abs(p_minus)))
        return (q1, self.legendre_plus(q, q1, h)), nfev

    def observe(self, state):
        """The reported node `dict(q, v, p, R=None)`: GNI $\\bar p$, $\\bar v$; RATTLE $\\tilde p$ (= gnipy's)."""
        if self.method == "rattle":
            q, p, _ = state
            return {"q": q, "v": p.copy(), "p": p, "R": None}
        q, p_plus = state
        _, p_bar, v_bar = reflect_and_report(self.G, self.mu(q), np.zeros(3), p_plus)
        return {"q": q, "v": v_bar, "p": p_bar, "R": None}

    def run(self, steps, h, save_all=False):
        """Integrate `steps` steps of size `h`; returns `dict(q, v, p, R=None, t, nfev)` (final node,
        or every node stacked with `save_all=True`)."""
        return _run(self, steps, h, save_all)


# ---------------------------------------------------------------------------------------------
# Lookup by name
# ---------------------------------------------------------------------------------------------

#: The cases and the gnipy method each one implements (the contact oscillator has two).
CASES = {
    "rolling_ball_ex2": (RollingBallEx2, ("gni-trapezoid",)),
    "contact_oscillator": (ContactOscillator, ContactOscillator.METHODS),
    "chaplygin_sphere": (ChaplyginSphere, ("gni-trapezoid",)),
}


def get_case(name, method=None, **kwargs):
    """A case object by name ("rolling_ball_ex2", "contact_oscillator", "chaplygin_sphere").

    `method` selects the contact oscillator's scheme ("rattle" or "gni-midpoint"); the balls only
    have "gni-trapezoid". Other keyword arguments go to the case's constructor.
    """
    if name not in CASES:
        raise ValueError(f"case: expected one of {tuple(CASES)}, got {name!r}")
    cls, methods = CASES[name]
    if method is not None and method not in methods:
        raise ValueError(f"method: case {name!r} implements {methods}, got {method!r}")
    if cls is ContactOscillator:
        return cls(method or "rattle", **kwargs)
    return cls(**kwargs)


def run(case, steps, h, method=None, save_all=False, **kwargs):
    """Run a case by name: `get_case(case, method, **kwargs).run(steps, h, save_all)`."""
    return get_case(case, method, **kwargs).run(steps, h, save_all)
