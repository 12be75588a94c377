"""The paper's errata (docs/conventions.md, "Errata"), each measured by running gnipy: the printed
form fails and the corrected one holds.

:func:`errata_rows` -> list of :class:`~gnipy.experiments.records.Erratum`:

- the sign of Π in (GNIredb-aff)/(RBb): the GNI on example 2 of §7.4 with Π → −Π against the five
  explicit equations of §7.4 (:func:`five_equations`) and the rolling constraints;
- Remark 5.1's two-step equation ($q_{k+1} - 2q_k + q_{k+1}$ printed), on RATTLE/SHAKE runs of the
  particle order study (:mod:`~gnipy.experiments.particle_study`);
- §7.4's model with unequal moments is not the physical Chaplygin sphere: continuous solutions
  (:class:`gnipy.ContinuousReference` through `gnipy.simulate(system, "reference", ...)`) of
  `rolling-ball` and `chaplygin-sphere` from the same start;
- the composition remark after Theorem 5.2: the literal composition of (EuBHam) and (EuAHam) is of
  order 1 (from the particle order study);
- the reading of (RATc): the inverse of the block $\\mathbb{G}_{xx}$, not the xx block of
  $\\mathbb{G}^{-1}$ (at the equation level; the full run also at the trajectory level).

Every run is a :func:`gnipy.simulate` call; the equations are evaluated on its saved nodes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..discrete_lagrangians import EulerA, Trapezoid
from ..errors import verdicts_reported_by_caller
from ..integrators.gni import GNI
from ..lie_groups import SO3
from ..methods import get_method
from ..models import get_model
from ..models import rolling_ball as rb
from ..simulate import simulate
from ..system import System
from . import particle_study as ps_study
from .records import Erratum, Progress, Work, all_nodes, bare, rel

__all__ = ["errata_rows", "cayley_steps", "five_equations"]


def cayley_steps(R, *, right: bool = False) -> np.ndarray:
    """σ_k = cay⁻¹(R_kᵀR_{k+1}) from consecutive attitudes, or cay⁻¹(R_{k+1}R_kᵀ) with `right` (R
    reconstructed as R_{k+1} = cay(σ_k)R_k, e.g. `rolling-ball`) (numpy; Appendix:
    cay⁻¹(Q) = 2 vee((Q − I)(Q + I)⁻¹)), shape (K − 1, 3)."""
    R = np.asarray(R, dtype=np.float64)
    Q = np.einsum("kij,klj->kil", R[1:], R[:-1]) if right else np.einsum("kji,kjl->kil", R[:-1], R[1:])
    eye = np.eye(3)
    S = 2.0 * (Q - eye) @ np.linalg.inv(Q + eye)
    return 0.5 * np.stack([S[:, 2, 1] - S[:, 1, 2], S[:, 0, 2] - S[:, 2, 0], S[:, 1, 0] - S[:, 0, 1]], axis=1)


def five_equations(p: dict, x, y, w, h: float) -> np.ndarray:
    """The five explicit equations of §7.4 (with their O(h) and O(h²) terms, the 4th and 5th with
    the correct sign of Π, as printed) at the nodes k = 1 .. K−1; rows are nodes, columns equations.

    Arguments:
        p: the parameters m, r, I1, I2, I3, Omega.
        x, y: the contact point at nodes 0..K.
        w: the step angular velocities ω^k = σ_k/h, k = 0..K−1.
        h: the step size.
    """
    m, r, I1, I2, I3, W = (p[k] for k in ("m", "r", "I1", "I2", "I3", "Omega"))
    I = np.array([I1, I2, I3])
    a, b = w[1:], w[:-1]  # ω^k, ω^{k−1}
    na, nb = (I * a**2).sum(1), (I * b**2).sum(1)  # ||ω||²_I
    x1, x0, xm = x[2:], x[1:-1], x[:-2]
    y1, y0, ym = y[2:], y[1:-1], y[:-2]
    e1 = (m * r * (x1 - 2 * x0 + xm) / h + I2 * (a[:, 1] - b[:, 1])
          + h / 2 * (I1 - I3) * (a[:, 0] * a[:, 2] + b[:, 0] * b[:, 2]) + h**2 / 4 * (a[:, 1] * na - b[:, 1] * nb))
    e2 = (m * r * (y1 - 2 * y0 + ym) / h - I1 * (a[:, 0] - b[:, 0])
          - h / 2 * (I3 - I2) * (a[:, 1] * a[:, 2] + b[:, 1] * b[:, 2]) - h**2 / 4 * (a[:, 0] * na - b[:, 0] * nb))
    e3 = (I3 * (a[:, 2] - b[:, 2]) + h / 2 * (I2 - I1) * (a[:, 0] * a[:, 1] + b[:, 0] * b[:, 1])
          + h**2 / 4 * (a[:, 2] * na - b[:, 2] * nb))
    e4 = ((x1 - xm) / (2 * h) + W * y0 - r * (a[:, 1] + b[:, 1]) / 2
          - r * h / 4 * (I1 - I3) / I2 * (a[:, 0] * a[:, 2] - b[:, 0] * b[:, 2])
          - h**2 / (8 * I2) * r * (a[:, 1] * na + b[:, 1] * nb))
    e5 = ((y1 - ym) / (2 * h) - W * x0 + r * (a[:, 0] + b[:, 0]) / 2
          + r * h / 4 * (I3 - I2) / I1 * (a[:, 1] * a[:, 2] - b[:, 1] * b[:, 2])
          + h**2 / (8 * I1) * r * (a[:, 0] * na + b[:, 0] * nb))
    return np.stack([e1, e2, e3, e4, e5], axis=1)


def _rolling_ball_nodes(system, q0, v0, h: float, steps: int):
    """`(x, R, v)` at the nodes 0..steps of the GNI (Euler A l_d, Cayley) on a rolling-ball System,
    from v0 projected onto the constraints."""
    with verdicts_reported_by_caller():
        sol = simulate(system, GNI(EulerA(), start="rest"), q0, v0, h=h, steps=steps, project_v0=True)
    return np.asarray(sol.q), np.asarray(sol.R), np.asarray(sol.v)


def _erratum_sign(quick: bool) -> Erratum:
    """(GNIredb-aff)/(RBb) print +2Q*Π: the GNI with Π → −Π (Ω → −Ω in Y) on example 2."""
    p = dict(rb.EXAMPLE_2["params"])
    _, q0, v0 = rb.example_2()
    h, steps = 0.1, 40 if quick else 150
    scale_G = np.array([p["m"], p["m"], p["I1"], p["I2"], p["I3"]])
    out = {}
    for label, W in (("corrected", p["Omega"]), ("printed", -p["Omega"])):
        # Y = (−Ωy, Ωx, 0, 0, 0): negating Ω negates Y and Π = 𝔾Y, i.e. it imposes
        # Q*((FL⁻ + FL⁺)/2 + Π) = 0, which is (RBb) as printed
        system = rb.build_system(dict(p, Omega=W), defaults=(q0, v0))
        x, R, v = _rolling_ball_nodes(system, q0, v0, h, steps)
        w = cayley_steps(R, right=system.reconstruction == "right") / h
        eq = np.max(np.abs(five_equations(p, x[:, 0], x[:, 1], w, h)), axis=0)
        pbar = v * scale_G
        rel_eq = eq / np.array([np.max(np.abs(pbar))] * 3 + [np.max(np.abs(v))] * 2)
        true_res = np.stack([v[:, 0] - p["r"] * v[:, 3] + p["Omega"] * x[:, 1],
                             v[:, 1] + p["r"] * v[:, 2] - p["Omega"] * x[:, 0]], axis=1)  # (Cona), (Conb)
        out[label] = {"eq123": float(np.max(rel_eq[:3])), "eq45": float(np.max(rel_eq[3:])),
                      "constraints": float(np.max(np.abs(true_res)) / np.max(np.abs(v)))}
    pr, co = out["printed"], out["corrected"]
    return Erratum(
        location="§7.3 (GNIredb-aff) and §7.4 (RBb)",
        printed="Q*(FL⁻_k) + Q*(FL⁺_k) + 2Q*Π = 0",
        corrected="Q*(FL⁻_k) + Q*(FL⁺_k) − 2Q*Π = 0, i.e. Q*((FL⁻ + FL⁺)/2 − Π) = 0, as in (GNIintAffb) "
                  "and as the 4th and 5th explicit equations of §7.4 are printed",
        measurement=(f"Rolling ball, example 2 (I = (1, 1.1, 1.2), m = 3, Ω = 0.2), GNI with the paper's l_d and "
                     f"Cayley, h = {h}, {steps} steps. The printed sign is the GNI with Π → −Π (a System with Y "
                     f"negated). Relative residual of the §7.4 equations 4–5: printed {pr['eq45']:.2f}, corrected "
                     f"{co['eq45']:.1e}; of the rolling constraints (Cona), (Conb) for the reported velocity: printed "
                     f"{pr['constraints']:.2f}, corrected {co['constraints']:.1e}. Equations 1–3 (the P* part, which "
                     f"the sign does not touch) hold for both ({max(pr['eq123'], co['eq123']):.1e})."),
        evidence_value=pr["eq45"],
        values={"printed_residual": pr["eq45"], "corrected_residual": co["eq45"],
                "printed_constraint_residual": pr["constraints"], "corrected_constraint_residual": co["constraints"],
                "equations_1_3_residual": max(pr["eq123"], co["eq123"])},
    )


@jit
def _node_terms(system, q):
    """M⁻¹V_q(q_k) and the projector P = I − M⁻¹μᵀC⁻¹μ at a batch of configurations."""

    def one(x):
        M, mu = system.metric(x), system.mu(x)
        Minv_muT = jnp.linalg.solve(M, mu.T)
        P = jnp.eye(x.shape[0]) - Minv_muT @ jnp.linalg.solve(mu @ Minv_muT, mu)
        return jnp.linalg.solve(M, system.potential_gradient(x)), P

    return jax.vmap(one)(q)


def _erratum_remark_5_1(quick: bool) -> Erratum:
    """Remark 5.1 prints q_{k+1} − 2q_k + q_{k+1}: residual of both two-step forms on RATTLE/SHAKE."""
    study = ps_study.particle_study(quick)
    key = "rattle" if quick else "shake"
    q = study["runs"][key][-1]["q"]
    h = study["hs"][-1]
    qm, qk, qp = q[:-2], q[1:-1], q[2:]
    MinvVq, P = (np.asarray(a) for a in _node_terms(study["system"], jnp.asarray(qk)))
    # the size of the terms the corrected equation balances: the second difference and h²M⁻¹V_q
    scale = float(np.max(np.abs(qp - 2 * qk + qm)) + np.max(np.abs(h * h * MinvVq)))

    def residual(second):  # P(q_{k+1} − 2q_k + second + h²M⁻¹V_q): the multiplier term drops out under P
        return float(np.max(np.abs(np.einsum("kij,kj->ki", P, qp - 2 * qk + second + h * h * MinvVq)))) / scale

    printed, corrected = residual(qp), residual(qm)
    return Erratum(
        location="Remark 5.1 (two-step SHAKE of McLachlan–Perlmutter)",
        printed="q_{k+1} − 2q_k + q_{k+1} = −h²M⁻¹(V_q(q_k) + μᵀ(q_k)λ̃_k)",
        corrected="q_{k+1} − 2q_k + q_{k−1} = −h²M⁻¹(V_q(q_k) + μᵀ(q_k)λ̃_k)",
        measurement=(f"Nonholonomic particle, {key} (= RATTLE = GNI with the trapezoid l_d), h = T/{study['Ns'][-1]}, "
                     f"{study['Ns'][-1]} steps. Residual of the equation projected by P = I − M⁻¹μᵀC⁻¹μ (which "
                     f"removes the unknown λ̃_k), relative to the size of its terms (the second difference and "
                     f"h²M⁻¹V_q, O(h²)): printed {printed:.1e} (it is off by 2(q_{{k+1}} − q_k) = O(h)), corrected "
                     f"{corrected:.1e} (round-off eps·|q|/h²)."),
        evidence_value=printed,
        values={"printed_residual": printed, "corrected_residual": corrected},
    )


def _sphere_systems(p: dict):
    """The paper's `rolling-ball` and the physical `chaplygin-sphere` for parameters `p`, under
    shared static metadata (one compilation per model for all parameter values)."""
    ball = bare(rb.build_system(p))
    sphere = bare(get_model("chaplygin-sphere").system(**p))
    return ball, sphere


def _continuous(system, q0, v0, t_final: float, saves: int):
    """`(q, v, R)` at t = k·t_final/saves, k = 0..saves, of the continuous solution
    (:class:`gnipy.ContinuousReference`, Dopri8 at tolerance 1e-12, landing a step on each time), R0 = I."""
    sol = simulate(system, "reference", q0, v0, R0=np.eye(3), h=t_final / saves, steps=saves)
    return np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.R)


def _erratum_sphere(quick: bool) -> Erratum:
    """§7.4's model with unequal moments is not the physical Chaplygin sphere."""
    p = dict(rb.EXAMPLE_2["params"])
    _, q0, v0 = rb.example_2()  # at R0 = I the body and space angular velocities agree
    T = 15.0
    gaps = {}
    for label, params in (("unequal", p), ("equal", dict(p, I1=1.1, I2=1.1, I3=1.1))):
        ball, sphere = _sphere_systems(params)
        xb, vb, _ = _continuous(ball, q0, v0, T, 30)
        xs, vs, Rs = _continuous(sphere, q0, v0, T, 30)
        # the model's ω is the space angular velocity: compare with the sphere's RΩ
        ws = np.einsum("kij,kj->ki", Rs, vs[:, 2:])
        gaps[label] = (float(np.max(np.linalg.norm(xb - xs, axis=1))), float(np.max(np.abs(vb[:, 2:] - ws))))
    return Erratum(
        location="§7.4 (Cona), (Conb), (LagCont)",
        printed="ẋ − rω₂ + Ωy = 0, ẏ + rω₁ − Ωx = 0 with ω the body angular velocity and l = ½m|ẋ|² + ½Σ Iᵢωᵢ², "
                "presented as the Chaplygin sphere with three different moments",
        corrected="the rolling constraints involve the space angular velocity Rω (attitude-dependent constraints, "
                  "model chaplygin-sphere); the paper's model is that sphere only for I1 = I2 = I3 (kept as "
                  "rolling-ball, which Fig. 3 integrates)",
        measurement=(f"Continuous solutions (gnipy.ContinuousReference: gnipy's equations by Dopri8, tolerance 1e-12) of rolling-ball and "
                     f"chaplygin-sphere from the same initial condition (example 2: (x, y) = (1, 0), R0 = I, "
                     f"ω0 = (−0.2, 0, 0.4), m = 3, Ω = 0.2) up to t = {T:g}. Unequal moments (1, 1.1, 1.2): the "
                     f"contact points differ by up to {gaps['unequal'][0]:.2f} (and the model's ω from the sphere's "
                     f"space angular velocity by {gaps['unequal'][1]:.2f}). Equal moments (1.1, 1.1, 1.1): they agree "
                     f"to {gaps['equal'][0]:.1e} ({gaps['equal'][1]:.1e} in ω)."),
        evidence_value=gaps["unequal"][0],
        values={"printed_residual": gaps["unequal"][0], "corrected_residual": gaps["equal"][0],
                "omega_gap_unequal": gaps["unequal"][1], "omega_gap_equal": gaps["equal"][1]},
    )


def _erratum_composition(quick: bool) -> Erratum:
    """The literal composition of (EuBHam) and (EuAHam) is of order 1; the re-read one of order 2."""
    study = ps_study.particle_study(quick)
    lit, rer = study["orders"]["euler-ab-literal"], study["orders"]["euler-ab"]
    return Erratum(
        location="Remark after Theorem 5.2 (composition F_A^{h/2} ∘ F_B^{h/2})",
        printed="the composition (time step h/2) of (EuAHam) and (EuBHam) generates a second-order method since "
                "the two are each other's adjoint",
        corrected="composed literally on (q, p̃, λ̃) it is of order 1: the two maps read p̃ differently "
                  "(p̄ = p̃ ∓ (h/4)V_q for B and A at step h/2), so the output of one does not lie where the other "
                  "starts and Theorem 5.2 does not apply at the junctions; with p̃ re-read there "
                  "(p̃ ← p̃ ± (h/2)V_q, i.e. the GNI flows composed) it is of order 2 (gnipy method euler-ab)",
        measurement=(f"Nonholonomic particle, h = T/{study['Ns'][0]} … T/{study['Ns'][-1]}, T = {ps_study.T_ORDER:g}, against "
                     f"the continuous reference: fitted order of the literal composition {lit:.2f}, of the re-read "
                     f"composition {rer:.2f}."),
        evidence_value=lit,
        values={"printed_order": lit, "corrected_order": rer},
    )


# A reduced system with a coupling block G_xξ ≠ 0 (where the two readings of (RATc) differ),
# a potential V(x) and x-dependent constraint rows (μ(x), η(x)).
_G_XX = np.array([[2.0, 0.3], [0.3, 1.5]])
_G_XS = np.array([[0.2, -0.1, 0.05], [0.0, 0.15, -0.1]])
_G_SS = np.array([[1.0, 0.1, 0.0], [0.1, 1.3, -0.05], [0.0, -0.05, 0.8]])
_METRIC = np.block([[_G_XX, _G_XS], [_G_XS.T, _G_SS]])


def _coupled_lagrangian(x, v):
    V = 0.5 * (x[0] ** 2 + 2.0 * x[1] ** 2) + 0.1 * jnp.sin(x[0] * x[1])
    return 0.5 * v @ jnp.asarray(_METRIC) @ v - V


def _coupled_mu(x):
    one, zero = jnp.ones_like(x[0]), jnp.zeros_like(x[0])
    return jnp.stack([jnp.stack([one, zero, zero, -one, 0.2 * jnp.sin(x[1])]),
                      jnp.stack([0.3 * x[0], one, 0.8 * one, zero, 0.1 * x[1]])])


def _erratum_ratc(quick: bool) -> Erratum:
    """(RATc): (G̃⁻¹)^{ij} is the inverse of the block G_xx, not the xx block of G⁻¹."""
    Gxx_inv, block_of_inv = np.linalg.inv(_G_XX), np.linalg.inv(_METRIC)[:2, :2]
    # equation level: x_{k+1} from (RATc) with p_{k+1/2} as §7.2 defines it, for random steps
    rng = np.random.default_rng(7)
    D, xi = rng.standard_normal((64, 2)), rng.standard_normal((64, 3))
    p_half = D @ _G_XX.T + xi @ _G_XS.T  # (p_{k+1/2})_i = G_ij Δ^j + G_is ξ^s
    rhs = p_half - xi @ _G_XS.T
    eq_right = float(np.max(np.abs(rhs @ Gxx_inv.T - D)) / np.max(np.abs(D)))
    eq_wrong = float(np.max(np.abs(rhs @ block_of_inv.T - D)) / np.max(np.abs(D)))
    values = {"equation_right": eq_right, "equation_wrong": eq_wrong}
    measurement = (f"Coupled reduced test system on R² × SO(3) (constant metric with G_xξ ≠ 0). Equation level: x_{{k+1}} "
                   f"recovered from (RATc) with p_{{k+1/2}} as defined in §7.2, relative error over 64 random steps: "
                   f"inverse of G_xx {eq_right:.1e}, xx block of G⁻¹ {eq_wrong:.1e}.")
    printed_value, corrected_value = eq_wrong, eq_right
    if not quick:  # trajectory level: RAT with each reading against the GNI with the trapezoid l_d
        from ..integrators.reduced_rattle import ReducedRattle

        class _BlockOfInverse(ReducedRattle):
            @staticmethod
            def _blocks(system, R):
                G, _, Gxs = ReducedRattle._blocks(system, R)
                return G, jnp.linalg.inv(jnp.linalg.inv(G)[:2, :2]), Gxs

        s = System(_coupled_lagrangian, _coupled_mu, n=2, group=SO3(), retraction="cayley", name="coupled-reduced")
        q0, v0 = np.array([0.5, -0.3]), np.array([0.4, -0.2, 0.3, 0.5, -0.6])
        kw = dict(R0=np.eye(3), project_v0=True, h=0.05, steps=200)
        gni = all_nodes(s, GNI(Trapezoid(), start="rest"), q0, v0, **kw)
        right = all_nodes(s, get_method("rat"), q0, v0, **kw)
        wrong = all_nodes(s, _BlockOfInverse(), q0, v0, **kw)
        corrected_value, printed_value = rel(right["q"], gni["q"]), rel(wrong["q"], gni["q"])
        values.update(trajectory_right=corrected_value, trajectory_wrong=printed_value)
        measurement += (f" Trajectory level (h = 0.05, 200 steps): max relative |x − x_GNI| of (RAT) against the GNI "
                        f"with the trapezoid l_d: inverse of G_xx {corrected_value:.1e}, xx block of G⁻¹ "
                        f"{printed_value:.1e}.")
    values.update(printed_residual=printed_value, corrected_residual=corrected_value)
    return Erratum(
        location="§7.2 (RATc)",
        printed="x_{k+1} = x_k + h (𝔾̃⁻¹)^{ij}((p_{k+1/2})_j − 𝔾̃_{jt} ξ_k^t), with the symbol 𝔾̃⁻¹ that denotes the "
                "inverse of the whole metric in A^{i,a}, B^{t,a}",
        corrected="(𝔾̃⁻¹)^{ij} in (RATc) is the inverse of the block 𝔾̃_{ij} (from the definition of p_{k+1/2}); "
                  "the two readings differ when 𝔾̃_{it} ≠ 0",
        measurement=measurement,
        evidence_value=printed_value,
        values=values,
    )


def errata_rows(quick: bool, progress: Progress = None) -> list[Erratum]:
    """Measure each erratum of the paper (docs/conventions.md, "Errata"): the printed form fails, the
    corrected form holds (module docstring).

    Arguments:
        quick: the short run.
        progress: optional `progress(advance, description)`; the advances add up to 1.0.

    Returns:
        The errata: the sign of Π in (GNIredb-aff)/(RBb); Remark 5.1's two-step equation; §7.4's
        model against the physical Chaplygin sphere; the composition remark; the reading of (RATc).
    """
    # the particle study is shared with theorem_table (cached): when it has not run yet, the
    # first erratum that needs it (Remark 5.1) runs it
    remark_weight = 0.5 if ps_study.study_done(quick) else 10.0
    steps = [("sign", _erratum_sign, 4.0), ("remark", _erratum_remark_5_1, remark_weight), ("sphere", _erratum_sphere, 3.0),
             ("composition", _erratum_composition, 0.5), ("ratc", _erratum_ratc, 0.2 if quick else 6.0)]
    work = Work(progress, {key: w for key, _, w in steps})
    out = []
    for key, fn, _ in steps:
        out.append(fn(quick))
        work(key, f"errata: {out[-1].location}")
    work.finish("errata: done")
    return out
