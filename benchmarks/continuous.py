"""The continuous equations of the benchmark cases, for `scipy.integrate.solve_ivp(method="DOP853")`.

This is the other baseline: what a researcher integrates when no structure-preserving method is at
hand. The Lagrange–d'Alembert(–Poincaré) equations (gnipy's docs, theory page, "The continuous
reference"), for $l = \\tfrac12 v^T\\mathbb{G}v - V$ with a constant metric and constraints
$\\mu(b)(v - Y(b)) = 0$:

$$\\mathbb{G}\\dot v = F + \\mu^T\\lambda, \\qquad F = (-\\nabla_x V,\\ \\mathrm{ad}^*_\\Omega I\\Omega) =
(-\\nabla_x V,\\ I\\Omega\\times\\Omega),$$

with λ from the differentiated constraints $\\mu\\dot v = c := \\mu\\,\\dot Y - \\dot\\mu(v - Y)$:
$\\lambda = C^{-1}(c - \\mu\\mathbb{G}^{-1}F)$, $C = \\mu\\mathbb{G}^{-1}\\mu^T$, and the reconstruction
$\\dot R = R\\hat\\Omega$ ($\\dot R = \\hat\\Omega R$ for the rolling ball, whose Ω is the space angular
velocity) integrated entrywise (9 entries of R; R drifts off SO(3) at the level of the
tolerance, as it does in any researcher's script). The right-hand sides are written by hand for
each model (NumPy, no JAX): that is the work this baseline stands for.

State layouts (as gnipy's reference packs them): the balls $y = (x, y, \\mathrm{vec}\\,R, \\dot x, \\dot y, \\Omega)$
(R row-major, 16 entries); the contact oscillator $y = (q, \\dot q)$ (6 entries).

Public functions: :func:`solve`, :func:`reference`, :func:`tuned_dop853`, :func:`final_error`,
:func:`get_case`; each case object offers the same as methods.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from .numpy_gni import ChaplyginSphere, ContactOscillator, RollingBallEx2, hat

__all__ = [
    "CASES",
    "ContinuousBall",
    "ContinuousChaplyginSphere",
    "ContinuousContactOscillator",
    "ContinuousRollingBallEx2",
    "final_error",
    "get_case",
    "reference",
    "solve",
    "tuned_dop853",
]

REFERENCE_RTOL = 1e-13
REFERENCE_ATOL = 1e-15
#: The default scan of :func:`tuned_dop853`, loose to tight, in half decades.
RTOL_GRID = tuple(10.0 ** (-k / 2) for k in range(6, 27))  # 1e-3 ... 1e-13


def final_error(state, ref):
    """The error norm of the benchmark: the largest absolute difference over the final q, v and R.

    Both arguments are dicts with `q`, `v` and (for the balls) `R`, e.g. the output of
    :func:`solve`, of :func:`reference`, of `numpy_gni.run` or of a gnipy Solution's last node
    (`dict(q=sol.q[-1], v=sol.v[-1], R=sol.R[-1])`). For the GNI, `v` is its reported $\\bar v$.
    """
    err = max(np.max(np.abs(np.asarray(state[k]) - np.asarray(ref[k]))) for k in ("q", "v"))
    if ref.get("R") is not None:
        err = max(err, np.max(np.abs(np.asarray(state["R"]) - np.asarray(ref["R"]))))
    return float(err)


class _ContinuousCase:
    """Shared driver: `solve`, `reference`, `tuned_dop853` around a hand-written `rhs`."""

    name = "case"
    gnipy_model = ""

    def y0(self):
        """The initial state vector."""
        raise NotImplementedError

    def rhs(self, t, y):
        """The right-hand side $\\dot y = f(t, y)$."""
        raise NotImplementedError

    def unpack(self, y):
        """`dict(q, v, R)` from a state vector (R is None without a group)."""
        raise NotImplementedError

    def solve(self, t_final, rtol, atol, *, method="DOP853", t_eval=None):
        """Integrate from t = 0 to `t_final` with `solve_ivp`.

        Returns:
            the final state `dict(q, v, R)` plus `nfev`, `nsteps` (accepted steps, counted from
            the solution's time points when `t_eval` is None) and `sol` (the OdeResult).
        """
        sol = solve_ivp(self.rhs, (0.0, float(t_final)), self.y0(), method=method, rtol=rtol, atol=atol,
                        t_eval=t_eval)
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed: {sol.message}")
        out = self.unpack(sol.y[:, -1])
        out.update(nfev=int(sol.nfev), nsteps=len(sol.t) - 1 if t_eval is None else None, sol=sol)
        return out

    def reference(self, t_final, method="dop853"):
        """The reference final state at `t_final`.

        `method="dop853"`: :meth:`solve` at rtol = 1e-13, atol = 1e-15. `method="gnipy"`: gnipy's
        `"reference"` method (diffrax Dopri8 at 1e-12, imports gnipy and JAX).
        """
        if method == "dop853":
            return self.solve(t_final, REFERENCE_RTOL, REFERENCE_ATOL)
        if method != "gnipy":
            raise ValueError(f"method: expected 'dop853' or 'gnipy', got {method!r}")
        import gnipy

        system = gnipy.make_system(self.gnipy_model, **self.params)
        R0 = None if self.unpack(self.y0())["R"] is None else self.R0
        sol = gnipy.simulate(system, "reference", self.q0, self.v0, R0=R0, h=float(t_final), steps=1)
        return {"q": np.asarray(sol.q[-1]), "v": np.asarray(sol.v[-1]),
                "R": None if sol.R is None else np.asarray(sol.R[-1])}

    def tuned_dop853(self, target_error, reference_final_state, t_final, *, atol_ratio=1e-3,
                     rtol_grid=RTOL_GRID, refine=6):
        """The loosest DOP853 tolerance whose final error is at most `target_error`.

        Scans `rtol_grid` from loose to tight (atol = rtol·`atol_ratio`) until the error
        (:func:`final_error` against `reference_final_state`) is below the target, then bisects
        `refine` times in log(rtol) between the last failing and the first passing tolerance,
        keeping the loosest passing one (the error is not exactly monotonic in rtol, so this is a
        scan, not a guarantee).

        Returns:
            `(rtol, nfev, error)` of the chosen tolerance; if even the tightest tolerance of the
            grid misses the target, that tolerance's triple (with error > target).
        """
        last_fail, best = None, None
        for rtol in rtol_grid:
            out = self.solve(t_final, rtol, rtol * atol_ratio)
            err = final_error(out, reference_final_state)
            if err <= target_error:
                best = (float(rtol), out["nfev"], err)
                break
            last_fail = (float(rtol), out["nfev"], err)
        if best is None:
            return last_fail
        if last_fail is not None:
            lo, hi = np.log10(best[0]), np.log10(last_fail[0])  # lo passes, hi fails
            for _ in range(int(refine)):
                mid = 0.5 * (lo + hi)
                rtol = 10.0**mid
                out = self.solve(t_final, rtol, rtol * atol_ratio)
                err = final_error(out, reference_final_state)
                if err <= target_error:
                    best, lo = (float(rtol), out["nfev"], err), mid
                else:
                    hi = mid
        return best


# ---------------------------------------------------------------------------------------------
# Balls on R^2 x SO(3)
# ---------------------------------------------------------------------------------------------


class ContinuousBall(_ContinuousCase):
    """A ball on $\\mathbb{R}^2\\times SO(3)$ with $l = \\tfrac12 m|\\dot x|^2 + \\tfrac12\\Omega^TI\\Omega$.

    No potential, $l$ independent of $(x, R)$: $F = (0, 0, I\\Omega\\times\\Omega)$ (Euler's
    equations). Subclasses give $\\mu$, its derivative along the motion $\\dot\\mu$, and
    $Y = (-\\Omega_t y, \\Omega_t x, 0, 0, 0)$ with $\\dot Y = (-\\Omega_t\\dot y, \\Omega_t\\dot x, 0, 0, 0)$.
    """

    discrete = None  # the numpy_gni case holding the parameters and the initial condition

    def __init__(self, params=None, q0=None, v0=None, R0=None):
        d = self.discrete(params, q0, v0, R0)
        self.params, self.q0, self.v0, self.R0 = d.params, d.q0, d.v0, d.R0
        self.m, self.r, self.inertia = d.m, d.r, d.inertia
        self.Gdiag = np.array([self.m, self.m, *self.inertia])
        self._mu = d.mu
        self.Omega_t = self.params["Omega"]
        self.space_angular_velocity = d.space_angular_velocity

    def y0(self):
        """$(x_0, \\mathrm{vec}\\,R_0, v_0)$."""
        return np.concatenate([self.q0, self.R0.reshape(-1), self.v0])

    def unpack(self, y):
        """`dict(q, v, R)`."""
        return {"q": y[:2], "v": y[11:], "R": y[2:11].reshape(3, 3)}

    def mu_dot(self, x, R, v):
        """$\\dot\\mu$: the derivative of μ along the motion."""
        raise NotImplementedError

    def rhs(self, t, y):
        """$(\\dot x, \\mathrm{vec}(R\\hat\\Omega), \\dot v)$ with $\\dot v$ from the Lagrange–d'Alembert–Poincaré equations
        ($\\hat\\Omega R$ for a space angular velocity)."""
        x, R, v = y[:2], y[2:11].reshape(3, 3), y[11:]
        Om = v[2:]
        W = self.Omega_t
        F = np.concatenate([[0.0, 0.0], np.cross(self.inertia * Om, Om)])  # ad*_Ω(IΩ) = IΩ × Ω
        mu = self._mu(x, R)
        Y = np.array([-W * x[1], W * x[0], 0.0, 0.0, 0.0])
        Y_dot = np.array([-W * v[1], W * v[0], 0.0, 0.0, 0.0])
        c = mu @ Y_dot - self.mu_dot(x, R, v) @ (v - Y)
        Ginv_F = F / self.Gdiag
        Ginv_muT = mu.T / self.Gdiag[:, None]
        lam = np.linalg.solve(mu @ Ginv_muT, c - mu @ Ginv_F)
        v_dot = Ginv_F + Ginv_muT @ lam
        R_dot = hat(Om) @ R if self.space_angular_velocity else R @ hat(Om)
        return np.concatenate([v[:2], R_dot.reshape(-1), v_dot])


class ContinuousRollingBallEx2(ContinuousBall):
    """The paper's rolling ball, example 2 (constant μ, so $\\dot\\mu = 0$). See `numpy_gni.RollingBallEx2`."""

    name = "rolling_ball_ex2"
    gnipy_model = "rolling-ball"
    discrete = RollingBallEx2

    def mu_dot(self, x, R, v):
        """Zero: μ is constant (the paper's model uses body angular velocities)."""
        return np.zeros((2, 5))


class ContinuousChaplyginSphere(ContinuousBall):
    """The physical Chaplygin sphere, $\\mu(R) = [[1, 0, -rR_{2,:}], [0, 1, rR_{1,:}]]$.

    $\\dot R = R\\hat\\Omega$ gives $\\dot\\mu = [[0, 0, -r(R\\hat\\Omega)_{2,:}], [0, 0, r(R\\hat\\Omega)_{1,:}]]$.
    (Its product with $v - Y$ is $\\pm r(R(\\Omega\\times\\Omega))_i = 0$; it is kept for clarity.)
    """

    name = "chaplygin_sphere"
    gnipy_model = "chaplygin-sphere"
    discrete = ChaplyginSphere

    def mu_dot(self, x, R, v):
        """$\\dot\\mu$ along $\\dot R = R\\hat\\Omega$."""
        Rd = R @ hat(v[2:])
        r = self.r
        return np.array([[0.0, 0.0, *(-r * Rd[1])], [0.0, 0.0, *(r * Rd[0])]])


# ---------------------------------------------------------------------------------------------
# The contact oscillator on R^3
# ---------------------------------------------------------------------------------------------


class ContinuousContactOscillator(_ContinuousCase):
    """$\\ddot q = -\\nabla V + \\mu^T\\lambda$, $\\mu = (1, 0, y)$, $V = \\tfrac12(|q|^2 + \\varepsilon x^2z^2)$.

    $\\dot\\mu = (0, 0, \\dot y)$ and $Y = 0$, so $c = -\\dot y\\dot z$ and
    $\\lambda = (c + \\mu\\nabla V)/(1 + y^2)$.
    """

    name = "contact_oscillator"
    gnipy_model = "contact-oscillator"

    def __init__(self, params=None, q0=None, v0=None):
        d = ContactOscillator("rattle", params, q0, v0)
        self.params, self.q0, self.v0, self.R0 = d.params, d.q0, d.v0, None
        self._grad_V = d.grad_V

    def y0(self):
        """$(q_0, v_0)$."""
        return np.concatenate([self.q0, self.v0])

    def unpack(self, y):
        """`dict(q, v, R=None)`."""
        return {"q": y[:3], "v": y[3:], "R": None}

    def rhs(self, t, y):
        """$(\\dot q, \\ddot q)$."""
        q, v = y[:3], y[3:]
        mu = np.array([1.0, 0.0, q[1]])
        F = -self._grad_V(q)
        c = -v[1] * v[2]  # −μ̇ v
        lam = (c - mu @ F) / (mu @ mu)
        return np.concatenate([v, F + mu * lam])


# ---------------------------------------------------------------------------------------------
# Lookup by name and module-level functions
# ---------------------------------------------------------------------------------------------

CASES = {
    "rolling_ball_ex2": ContinuousRollingBallEx2,
    "contact_oscillator": ContinuousContactOscillator,
    "chaplygin_sphere": ContinuousChaplyginSphere,
}


def get_case(name, **kwargs):
    """The continuous case object by name (keyword arguments: params, q0, v0 and, for balls, R0)."""
    if name not in CASES:
        raise ValueError(f"case: expected one of {tuple(CASES)}, got {name!r}")
    return CASES[name](**kwargs)


def solve(case, t_final, rtol, atol, **kwargs):
    """`get_case(case).solve(t_final, rtol, atol, **kwargs)`: the final state plus `nfev`."""
    return get_case(case).solve(t_final, rtol, atol, **kwargs)


def reference(case, t_final, method="dop853"):
    """`get_case(case).reference(t_final, method)`: DOP853 at rtol 1e-13, atol 1e-15 (or gnipy's)."""
    return get_case(case).reference(t_final, method)


def tuned_dop853(case, target_error, reference_final_state, t_final, **kwargs):
    """`get_case(case).tuned_dop853(...)`: `(rtol, nfev, error)` of the loosest DOP853 tolerance
    whose :func:`final_error` is at most `target_error`."""
    return get_case(case).tuned_dop853(target_error, reference_final_state, t_final, **kwargs)
