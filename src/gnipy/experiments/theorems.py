"""The paper's theorems and its errata, measured by running gnipy.

Two calls, both `(quick, progress=None)`:

- :func:`theorem_table` -> list of :class:`Row`: each claim of the paper that gnipy can check by
  running it, with the paper's statement, the measured value and pass/fail:

  * Theorem 5.1 and the remarks of §5: fitted convergence orders of nonholonomic Euler A and B
    ((EuAHam), (EuBHam): 1), RATTLE ((nonholonomicRATTLE), [SDD2]: 2), the composition
    $F_A^{h/2}\\circ F_B^{h/2}$ (remark after Thm 5.2: 2), the GNI with the Euler A, Euler B,
    trapezoid and midpoint discrete Lagrangians (1, 1, 2, 2), on the nonholonomic particle against
    the continuous reference (:mod:`~gnipy.experiments.particle_study`; the expected order is the method's `order`);
  * Theorem 5.2: $F_A^h\\circ F_B^{-h} = \\mathrm{Id}$, residual over random constrained states
    (:mod:`~gnipy.experiments.identities`);
  * §4 (after (GNIloc)) and §6: the reported momentum of every GNI variant satisfies the
    constraints exactly;
  * §4 (end, [SDD1]): on SO(3) with a bi-invariant metric, an attitude-dependent distribution and
    a left-invariant $l_d$, the GNI conserves the energy: relative drift of $|p^+_k|$ over
    $10^4$ (quick) or $10^5$ steps (:mod:`~gnipy.experiments.identities`);
  * §5: the explicit schemes (EuAHam), (EuBHam), (nonholonomicRATTLE) are the GNI with the Euler A,
    Euler B and trapezoid $l_d$ (equal node by node).

- :func:`errata_rows` -> list of :class:`Erratum`: the misprints and readings of the paper
  (docs/conventions.md, "Errata"), each with a measurement that shows the printed form failing and
  the corrected one holding (:mod:`~gnipy.experiments.errata`).

Every run is a :func:`gnipy.simulate` call (the continuous reference too: `"reference"`). The
particle study is computed once per `quick` and shared by the table and the errata.

**Progress.** `progress(advance, description)` is called as work proceeds; the advances of one
call add up to 1.0 (as for the figures).
"""

from __future__ import annotations

import numpy as np

from .errata import cayley_steps, errata_rows, five_equations
from .identities import C_INERTIA, ENERGY_H, adjointness, constrained_tilde_states, energy_theorem, energy_theorem_system
from .particle_study import (
    EQUAL_PAIRS,
    GNI_VARIANTS,
    LD_NAMES,
    ORDER_REFS,
    T_ORDER,
    LiteralEulerABComposition,
    particle_study,
    spring_ball,
)
from .records import (
    EPS,
    EQUAL_PER_STEP,
    EQUAL_TOL,
    ORDER_TOL,
    ROUND_OFF,
    ROUNDOFF_WALK,
    Erratum,
    Progress,
    Row,
    Work,
    rel,
)

__all__ = [
    "Row",
    "Erratum",
    "theorem_table",
    "errata_rows",
    "constrained_tilde_states",
    "LiteralEulerABComposition",
    "five_equations",
    "cayley_steps",
    "energy_theorem_system",
    "ORDER_TOL",
    "ROUND_OFF",
]


def theorem_table(quick: bool, progress: Progress = None) -> list[Row]:
    """Measure the paper's claims with gnipy (module docstring); quick: fewer h and 10⁴ steps for
    the energy theorem instead of 10⁵.

    Arguments:
        quick: the short run (about 15 s on two cores, most of it compilation).
        progress: optional `progress(advance, description)`; the advances add up to 1.0.

    Returns:
        The rows, in the paper's order.
    """
    weights = {"reference": 1.0, **{k: 1.0 for k in [*ORDER_REFS, "euler-ab-literal", "shake"]},
               "affine": 3.0, "adjoint": 1.5, "energy": 8.0 if quick else 20.0}
    if quick:
        weights.pop("shake"), weights.pop("affine")
    work = Work(progress, weights)
    study = particle_study(quick, lambda key: work(key, f"theorems: particle runs ({key})"))
    Ns = study["Ns"]
    h_range = f"h = T/{Ns[0]} … T/{Ns[-1]}, T = {T_ORDER:g}"
    rows = [
        *_order_rows(study, h_range),  # Theorem 5.1, Remark 5.1, Remark after Theorem 5.2
        _adjoint_row(study, quick, work),  # Theorem 5.2
        *_momentum_rows(study, quick),  # exact constraints of the reported momentum
        *_equality_rows(study, quick, h_range),  # the explicit schemes are the GNI
        _energy_row(quick, work),  # the energy theorem
    ]
    work.finish("theorems: done")
    return rows


def _order_rows(study: dict, h_range: str) -> list[Row]:
    """The rows of the fitted convergence orders (Theorem 5.1, Remark 5.1, Remark after Theorem 5.2)."""
    hs = study["hs"]
    ref_note = (" Reference: gnipy.ContinuousReference (gnipy's Lagrange–d'Alembert equations by Dopri8 at "
                "tolerance 1e-12). Expected order: the method's `order`.")
    names = {"euler-a": "nonholonomic Euler A (EuAHam)", "euler-b": "nonholonomic Euler B (EuBHam)",
             "rattle": "nonholonomic RATTLE", "euler-ab": "composition Euler A(h/2) ∘ Euler B(h/2)",
             "gni-euler-a": "GNI, Euler A l_d", "gni-euler-b": "GNI, Euler B l_d",
             "gni-trapezoid": "GNI, trapezoid l_d", "gni-midpoint": "GNI, midpoint l_d"}
    rows = []
    for key, ref in ORDER_REFS.items():
        claim = study["expected"][key]
        order = study["orders"][key]
        errs = study["errors"][key]
        rows.append(Row(
            claim=f"{names[key]} ({key}) converges with order {claim}",
            paper_ref=ref,
            expected=f"order {claim}",
            measured=f"order {order:.2f}",
            passed=bool(abs(order - claim) <= ORDER_TOL),
            detail=(f"Nonholonomic particle, {h_range}; error = max |q − q_ref| at t = 0, 0.5, …, 2 "
                    f"({errs[0]:.2e} at the largest h, {errs[-1]:.2e} at the smallest); least-squares slope, "
                    f"tolerance ±{ORDER_TOL}." + ref_note),
            values={"method": key, "order": order, "expected": float(claim), "errors": list(errs), "hs": list(hs)},
        ))
    return rows


def _adjoint_row(study: dict, quick: bool, work: Work) -> Row:
    """The row of Theorem 5.2: F_A^h ∘ F_B^{−h} = Id on M_A."""
    cases = {"linear": study["system"]}
    if not quick:
        cases["affine"] = spring_ball()[0]
    adj = {name: adjointness(s) for name, s in cases.items()}
    res = max(a["residual"] for a in adj.values())
    work("adjoint", "theorems: Theorem 5.2")
    mb = max(a["manifold_B"] for a in adj.values())
    ma, od = min(a["manifold_A"] for a in adj.values()), min(a["off_domain"] for a in adj.values())
    return Row(
        claim="nonholonomic Euler A and B are each other's adjoint: F_A^h ∘ F_B^{−h} = Id",
        paper_ref="Theorem 5.2",
        expected="0 (identity)",
        measured=f"{res:.1e}",
        passed=bool(res <= EQUAL_TOL and mb <= EQUAL_TOL),
        detail=(f"max relative |F_A^h ∘ F_B^{{−h}}(s) − s| over {adj['linear']['states']} random states s = (q, p̃, λ̃) "
                "of M_A = {μM⁻¹(p̃ + (h/2)V_q − Π) = 0}, where F_A^h starts ((EuAHamc)), h = 0.1 and 0.01, on "
                + ("the nonholonomic particle" if quick else "the nonholonomic particle and an affine ball with a spring")
                + f"; tolerance {EQUAL_TOL:g}. F_B^{{−h}} maps M_A into itself (residual {mb:.1e}), so it is the "
                f"inverse of F_A^h there. Controls: the intermediate state moves (min max|Δq| "
                f"{min(a['moved'] for a in adj.values()):.2e}); from states off M_A the round trip fails ({od:.1e}); "
                f"F_A^{{−h}} leaves M_A ({ma:.1e}). Note: F_A^h depends on (p̃, λ̃) only through p_{{k+1/2}}, so as "
                "formulas F_A^h ∘ F_A^{−h} also returns every s of M_A; the adjoint is the map that stays on M_A."),
        values={"residual": res, "manifold_B": mb, "manifold_A": ma, "off_domain": od},
    )


def _momentum_rows(study: dict, quick: bool) -> list[Row]:
    """The rows of the exact constraints of every GNI variant's reported momentum (§4, (GNIintAffb))."""
    rows = []
    for key in GNI_VARIANTS:
        res_p = max(float(np.max(np.abs(r["residual"]))) for r in study["runs"][key])
        delta = max(float(np.max(np.abs(r["step_residual"]))) for r in study["runs"][key])
        where = "the nonholonomic particle (all nodes of every run)"
        if not quick:
            a = study["affine"][key]
            res_p = max(res_p, float(np.max(np.abs(a["residual"]))))
            where += " and the affine ball with a spring (h = 0.02, 1000 steps)"
        rows.append(Row(
            claim=f"the reported momentum p̄ = (p⁻ + p⁺)/2 of {key} satisfies the constraints",
            paper_ref="§4 after (GNIloc); (GNIintAffb)",
            expected="0 (exact)",
            measured=f"{res_p:.1e}",
            passed=bool(res_p <= EQUAL_TOL),
            detail=(f"max |μ(v̄ − Y)| with v̄ = 𝔾⁻¹p̄ on {where}; tolerance {EQUAL_TOL:g}. Control: the step "
                    f"velocity (q_{{k+1}} − q_k)/h violates them by up to {delta:.1e}."),
            values={"method": key, "residual": res_p, "step_velocity_residual": delta},
        ))
    return rows


def _equality_rows(study: dict, quick: bool, h_range: str) -> list[Row]:
    """The rows of the explicit schemes of §5 (and SHAKE, §6.1) equal to the GNI node by node."""
    rows = []
    for explicit, gni, label in EQUAL_PAIRS + ([] if quick else [("shake", "gni-trapezoid", "(Afin), SHAKE")]):
        pairs = list(zip(study["runs"][explicit], study["runs"][gni]))
        if not quick:
            pairs.append((study["affine"][explicit], study["affine"][gni]))
        diff = max(max(rel(e["q"], g["q"]), rel(e["v"], g["v"]), rel(e["p"], g["p"])) for e, g in pairs)
        tol = EQUAL_PER_STEP * max(len(e["q"]) - 1 for e, _ in pairs) * EPS
        rows.append(Row(
            claim=f"{label} ({explicit}) is the GNI with the {LD_NAMES[gni]} l_d ({gni})",
            paper_ref="§5 (EuAHam)/(EuBHam) from (GNIint); Remark 5.1" + ("; §6.1" if not quick else ""),
            expected="equal node by node",
            measured=f"{diff:.1e} (relative)",
            passed=bool(diff <= tol),
            detail=(f"max relative difference of q, v̄ and p̄ over all nodes of the particle runs ({h_range})"
                    + ("" if quick else " and of the affine ball with a spring (h = 0.02, 1000 steps)")
                    + f"; tolerance {EQUAL_PER_STEP:g}·N·eps = {tol:.1e} (round-off of N steps). The explicit maps "
                    "(gnipy.integrators.paper_schemes) are written separately from the GNI core."),
            values={"methods": (explicit, gni), "difference": diff, "tolerance": tol},
        ))
    return rows


def _energy_row(quick: bool, work: Work) -> Row:
    """The row of the energy theorem on SO(3) (§4, end; [SDD1]): 10⁴ (quick) or 10⁵ steps."""
    steps = 10_000 if quick else 100_000
    en = energy_theorem(steps)
    work("energy", "theorems: energy theorem on SO(3)")
    passed = en["drift"] <= en["bound"] and en["trend"] <= en["bound"] and en["constraint_residual"] <= EQUAL_TOL
    return Row(
        claim="on a Lie group with a bi-invariant metric, any distribution and a left-invariant l_d, the GNI "
              "conserves the energy",
        paper_ref="§4 (end of the section), [SDD1]",
        expected="0 drift (exact)",
        measured=f"{en['drift']:.1e} (relative drift of |p⁺| over {steps:,} steps)",
        passed=bool(passed),
        detail=(f"SO(3), l = ½c|Ω|² (c = {C_INERTIA}), V = 0, one random attitude-dependent constraint μ(R), "
                f"GNI with the Euler A l_d (left-invariant) and the Cayley map, h = {ENERGY_H}. The conserved energy is "
                f"|p⁺_k|²/2c: max_k ||p⁺_k|/|p⁺_0| − 1| = {en['drift']:.1e}, fitted trend over the run "
                f"{en['trend']:.1e}, both within the round-off model {ROUNDOFF_WALK:g}·√N·eps = {en['bound']:.1e}. "
                f"Reported v̄ on the constraints to {en['constraint_residual']:.0e}. Control: the energy of the "
                f"reported v̄ (a projection of p⁺) varies by {en['reported_energy_variation']:.1e} (relative)."),
        values=en,
    )


# ------------------------------------------------------------------------------------------------
# Errata
