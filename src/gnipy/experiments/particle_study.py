"""The order study on the nonholonomic particle, shared by the theorem table and the errata.

Each method integrates the nonholonomic particle ($l = \\tfrac12|\\dot q|^2 - \\tfrac12(x^2 + y^2)$,
$\\dot z = y\\dot x$) with h = T/N, T = 2, N = 2^j (j = 5..8 quick, 5..10 full). The error of a run
is the largest $|q - q_\\mathrm{ref}|$ at t = 0, 0.5, 1, 1.5, 2 against the continuous reference
(:class:`gnipy.ContinuousReference`, diffrax's Dopri8 at tolerance 1e-12, through
`gnipy.simulate(system, "reference", ...)`), and the order is
:func:`gnipy.analysis.fitted_order` over the points above round-off (1e-11, at least three). The
expected order of each method is its `order` (the one statement of it, on the method).

Every run is one :func:`gnipy.simulate` call that saves every node (:func:`~gnipy.experiments.records.all_nodes`):
the theorem table also checks the constraints and the equality of the explicit schemes with the
GNI at all nodes, and the errata read the two-step equation of Remark 5.1 off them. All runs take
the steps of the finest h (the nodes after t = T are dropped), so that they save as many nodes and
all runs of one method share one compiled program.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ..analysis.orders import ROUND_OFF, fitted_order
from ..integrators import paper_schemes as ps
from ..integrators.base import explicit_step_info
from ..methods import get_method
from ..models import get_model
from ..simulate import simulate
from ..system import System
from .records import all_nodes

__all__ = ["LiteralEulerABComposition", "particle_study", "study_done", "paper_method", "particle", "spring_ball",
           "ORDER_REFS", "T_ORDER", "SAVES"]


def paper_method(name: str):
    """The method `name` as the paper runs it: a GNI starts from rest, $p^+_0 = \\bar p_0$ (§4; the
    library's default is the consistent start, :class:`gnipy.GNI`), so that (EuAHam), (EuBHam) and
    (nonholonomicRATTLE) are the GNI step for step from the first node."""
    import dataclasses

    from ..integrators.gni import GNI

    method = get_method(name)
    return dataclasses.replace(method, start="rest") if isinstance(method, GNI) else method


class LiteralEulerABComposition(ps.EulerABComposition):
    """(EuAHam) at h/2 after (EuBHam) at h/2 on $(q, \\tilde p, \\tilde\\lambda)$, composed literally
    (no change of the $\\tilde p$ reading at the junctions; see :class:`gnipy.EulerABComposition`).
    Of order 1 (the errata: the two maps read $\\tilde p$ differently, so the composition is not
    of a map with its adjoint)."""

    name = "euler-ab-literal"
    order = 1

    def step(self, system, state, h):
        new = ps.euler_a_map(system, ps.euler_b_map(system, state, 0.5 * h), 0.5 * h)
        return new, explicit_step_info(*new)


#: Where the paper states each method's order (the order itself is the method's `order`).
ORDER_REFS = {
    "euler-a": "Theorem 5.1, (EuAHam)",
    "euler-b": "Theorem 5.1, (EuBHam)",
    "rattle": "Remark 5.1, (nonholonomicRATTLE), [SDD2]",
    "euler-ab": "Remark after Theorem 5.2",
    "gni-euler-a": "Theorem 5.1 (GNI with the Euler A l_d, (LagEuler))",
    "gni-euler-b": "Theorem 5.1 (GNI with the Euler B l_d, (LagEuler))",
    "gni-trapezoid": "Remark 5.1, (Verlet): GNI with the trapezoid l_d is RATTLE",
    "gni-midpoint": "§4, GNI with the midpoint l_d (symmetric)",
}
EQUAL_PAIRS = [("euler-a", "gni-euler-a", "(EuAHam)"), ("euler-b", "gni-euler-b", "(EuBHam)"),
               ("rattle", "gni-trapezoid", "(nonholonomicRATTLE)")]
GNI_VARIANTS = ["gni-euler-a", "gni-euler-b", "gni-trapezoid", "gni-midpoint"]
LD_NAMES = {"gni-euler-a": "Euler A", "gni-euler-b": "Euler B", "gni-trapezoid": "trapezoid", "gni-midpoint": "midpoint"}

T_ORDER = 2.0
SAVES = 4
_STUDY: dict[bool, dict] = {}


def particle():
    """`(system, q0, v0)` of the zoo model `nonholonomic-particle`."""
    spec = get_model("nonholonomic-particle")
    return spec.system(), np.asarray(spec.q0, dtype=np.float64), np.asarray(spec.v0, dtype=np.float64)


# Ball on a table turning at rate Ω with a spring (affine constraints and a potential), on R⁵:
# l = ½m(ẋ²+ẏ²) + ½I|ω|² − ½k(x²+y²); ẋ − rω₂ + Ωy = 0, ẏ + rω₁ − Ωx = 0.
_B = {"m": 1.0, "I": 0.4, "r": 1.0, "Omega": 0.7, "k": 1.0}


def _spring_ball_lagrangian(q, v):
    return (0.5 * _B["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * _B["I"] * (v[2:] @ v[2:])
            - 0.5 * _B["k"] * (q[0] ** 2 + q[1] ** 2))


def _spring_ball_mu(q):
    return jnp.array([[1.0, 0.0, 0.0, -_B["r"], 0.0], [0.0, 1.0, _B["r"], 0.0, 0.0]], dtype=q.dtype)


def _spring_ball_Y(q):
    z = jnp.zeros_like(q[0])
    return jnp.stack([-_B["Omega"] * q[1], _B["Omega"] * q[0], z, z, z])


def spring_ball():
    """`(system, q0, v0)`: an affine system with a potential (the ball on a turning table with a spring)."""
    s = System(_spring_ball_lagrangian, _spring_ball_mu, _spring_ball_Y, n=5, name="spring-ball-on-turning-table")
    q0 = np.array([1.0, 0.5, 0.0, 0.0, 0.0])
    w = np.array([0.3, -0.2, 0.5])
    v0 = np.array([_B["r"] * w[1] - _B["Omega"] * q0[1], -_B["r"] * w[0] + _B["Omega"] * q0[0], *w])
    return s, q0, v0


def study_done(quick: bool) -> bool:
    """Whether :func:`particle_study` has already run (and is kept) for `quick` in this process."""
    return quick in _STUDY


def particle_study(quick: bool, tick: Callable[[str], None] = lambda d: None) -> dict:
    """Every method's runs on the particle at every h, their errors against the reference, the
    fitted and the expected orders (cached per `quick`); the full study also runs the methods on
    the affine ball with a spring (h = 0.02, 1000 steps). `tick(key)` is called after each stage."""
    if quick in _STUDY:
        return _STUDY[quick]
    t_start = time.perf_counter()
    system, q0, v0 = particle()
    js = range(5, 9) if quick else range(5, 11)
    Ns = [2**j for j in js]
    hs = [T_ORDER / N for N in Ns]
    ref = simulate(system, "reference", q0, v0, h=T_ORDER / SAVES, steps=SAVES)  # t = 0, 0.5, ..., T
    q_ref = np.asarray(ref.q)
    tick("reference")
    methods = {name: paper_method(name) for name in ORDER_REFS}
    methods["euler-ab-literal"] = LiteralEulerABComposition()
    if not quick:
        methods["shake"] = paper_method("shake")
    runs: dict[str, list[dict]] = {}
    errors: dict[str, list[float]] = {}
    for key, method in methods.items():
        runs[key], errors[key] = [], []
        for N, h in zip(Ns, hs):
            out = all_nodes(system, method, q0, v0, h=h, steps=N, run_steps=Ns[-1])
            runs[key].append(out)
            errors[key].append(float(np.max(np.abs(out["q"][:: N // SAVES] - q_ref))))
        tick(key)
    orders = {key: fitted_order(hs, errors[key], ROUND_OFF, min_points=3) for key in methods}
    study = {"system": system, "q0": q0, "v0": v0, "hs": hs, "Ns": Ns, "runs": runs, "errors": errors,
             "orders": orders, "expected": {key: m.order for key, m in methods.items()},
             "runtime_s": time.perf_counter() - t_start}
    if not quick:
        s, bq0, bv0 = spring_ball()
        study["affine"] = {name: all_nodes(s, paper_method(name), bq0, bv0, h=0.02, steps=1000)
                           for name in ["euler-a", "euler-b", "rattle", "shake", *GNI_VARIANTS]}
        tick("affine")
    _STUDY[quick] = study
    return study
