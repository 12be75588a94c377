"""Method names (as used by the CLI) and the integrator objects they stand for.

A method's expected order is not stated here: it is the `order` of the integrator object
(`get_method(name).order`), which `gni methods` shows."""

from __future__ import annotations

from collections.abc import Callable

from .integrators.base import MethodError

__all__ = ["get_method", "method_names", "METHOD_DESCRIPTIONS"]


def _gni(ld_name: str):
    def make():
        from .discrete_lagrangians import DISCRETE_LAGRANGIANS
        from .integrators.gni import GNI

        return GNI(DISCRETE_LAGRANGIANS[ld_name]())

    return make


def _lazy(module: str, cls: str):
    def make():
        import importlib

        return getattr(importlib.import_module(module, __package__), cls)()

    return make


_METHODS: dict[str, tuple[str, Callable[[], object]]] = {
    "gni-euler-a": ("GNI with the Euler A discrete Lagrangian", _gni("euler-a")),
    "gni-euler-b": ("GNI with the Euler B discrete Lagrangian", _gni("euler-b")),
    "gni-trapezoid": ("GNI with the trapezoid (Störmer–Verlet) discrete Lagrangian: RATTLE", _gni("trapezoid")),
    "gni-midpoint": ("GNI with the midpoint discrete Lagrangian", _gni("midpoint")),
    "euler-a": ("nonholonomic Euler A, explicit (EuAHam) on (q, p̃, λ̃)",
                _lazy(".integrators.paper_schemes", "NonholonomicEulerA")),
    "euler-b": ("nonholonomic Euler B, explicit (EuBHam) on (q, p̃, λ̃)",
                _lazy(".integrators.paper_schemes", "NonholonomicEulerB")),
    "euler-ab": ("composition Euler A(h/2) ∘ Euler B(h/2)",
                 _lazy(".integrators.paper_schemes", "EulerABComposition")),
    "shake": ("nonholonomic SHAKE, two-step form (Remark 5.1, (Afin))",
              _lazy(".integrators.paper_schemes", "Shake")),
    "rattle": ("nonholonomic RATTLE, explicit (nonholonomicRATTLE), affine §6.1",
               _lazy(".integrators.paper_schemes", "Rattle")),
    "rat": ("reduced RATTLE algorithm (RAT) of §7.2 on R^n × G, constant metric", _lazy(".integrators.reduced_rattle", "ReducedRattle")),
    "dla": ("discrete Lagrange–d'Alembert (Cortés–Martínez), midpoint constraint",
            _lazy(".integrators.comparators", "DiscreteLagrangeDAlembert")),
    "mp": ("McLachlan–Perlmutter reversible scheme (4.18)",
           _lazy(".integrators.comparators", "McLachlanPerlmutter")),
    "reference": ("continuous Lagrange–d'Alembert equations, Dopri8 at tolerance 1e-12",
                  _lazy(".reference", "ContinuousReference")),
}

METHOD_DESCRIPTIONS: dict[str, str] = {k: v[0] for k, v in _METHODS.items()}


def method_names() -> list[str]:
    """All method names, in documentation order."""
    return list(_METHODS)


def get_method(name: str):
    """A fresh integrator object for a method name; unknown names raise MethodError."""
    if not isinstance(name, str) or name not in _METHODS:
        raise MethodError(f"method: unknown method {name!r} (known: {', '.join(_METHODS)})")
    return _METHODS[name][1]()
