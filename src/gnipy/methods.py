"""Method names (as used by the CLI) and the integrator objects they stand for.

A method's expected order is not stated here: it is the `order` of the integrator object
(`get_method(name).order`), which `gni methods` shows."""

from __future__ import annotations

from collections.abc import Callable

from .integrators.base import MethodError
from .registry import set_method_lookup

__all__ = ["get_method", "shared_method", "method_names", "is_method_name", "prepared_method", "METHOD_DESCRIPTIONS"]


def _gni(ld_name: str):
    def make():
        from .discrete_lagrangians import DISCRETE_LAGRANGIANS
        from .integrators.gni import GNI

        return GNI(DISCRETE_LAGRANGIANS[ld_name]())

    return make


def _sgni(ld_name: str):
    def make():
        from .discrete_lagrangians import DISCRETE_LAGRANGIANS
        from .integrators.gni_variants import SymmetricImpulseGNI

        return SymmetricImpulseGNI(DISCRETE_LAGRANGIANS[ld_name]())

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
    "sgni-trapezoid": ("GNI with one impulse per step acting at both ends (no hidden momentum), trapezoid l_d",
                       _sgni("trapezoid")),
    "sgni-midpoint": ("GNI with one impulse per step acting at both ends (no hidden momentum), midpoint l_d",
                      _sgni("midpoint")),
    "euler-a": ("nonholonomic Euler A, explicit (EuAHam) on (q, p̃, λ̃)",
                _lazy(".integrators.paper_schemes", "NonholonomicEulerA")),
    "euler-b": ("nonholonomic Euler B, explicit (EuBHam) on (q, p̃, λ̃)",
                _lazy(".integrators.paper_schemes", "NonholonomicEulerB")),
    "euler-ab": ("composition Euler A(h/2) ∘ Euler B(h/2)",
                 _lazy(".integrators.paper_schemes", "EulerABComposition")),
    "shake": ("nonholonomic SHAKE, two-step form (Remark 5.1, (Afin))",
              _lazy(".integrators.shake", "Shake")),
    "rattle": ("nonholonomic RATTLE, explicit (nonholonomicRATTLE), affine §6.1",
               _lazy(".integrators.paper_schemes", "Rattle")),
    "rat": ("reduced RATTLE algorithm (RAT) of §7.2 on R^n × G, constant metric", _lazy(".integrators.reduced_rattle", "ReducedRattle")),
    "dla": ("discrete Lagrange–d'Alembert (Cortés–Martínez), midpoint constraint",
            _lazy(".integrators.comparators", "DiscreteLagrangeDAlembert")),
    "mp": ("McLachlan–Perlmutter reversible scheme (4.18)",
           _lazy(".integrators.comparators", "McLachlanPerlmutter")),
    "sister": ("sister method: RATTLE on a rail tangent to the constraints at each node, then the plastic impact "
               "onto them (order 1, dissipative; open question 3), R^n and linear constraints",
               _lazy(".integrators.sister", "SisterMethod")),
    "discrete-gradient": ("energy-conserving discrete gradient, constraints exact at the nodes, symmetric",
                          _lazy(".integrators.discrete_gradient", "DiscreteGradient")),
    "reference": ("continuous Lagrange–d'Alembert equations, Dopri8 at tolerance 1e-12",
                  _lazy(".reference", "ContinuousReference")),
}


def _composed(scheme: str, base: str):
    def make():
        from .integrators.composition import Composition

        return Composition(get_method(base), scheme)

    return make


# The order-4 compositions of the GNI trapezoid (explicit on a flat space, hence the cheapest base)
# and the order-6 one of mp are listed; any other symmetric method composes by name,
# "<scheme>-<method>" (get_method).
_METHODS |= {
    "yoshida4-gni-trapezoid": ("Yoshida's triple jump of gni-trapezoid, impulse rescaled, consistent start: order 4",
                               _composed("yoshida4", "gni-trapezoid")),
    "suzuki4-gni-trapezoid": ("Suzuki's 5-stage composition of gni-trapezoid: order 4",
                              _composed("suzuki4", "gni-trapezoid")),
    "kahanli6-mp": ("Kahan–Li's 9-stage composition of mp: order 6 (of a GNI it reaches order 4 only)",
                    _composed("kahanli6", "mp")),
}

METHOD_DESCRIPTIONS: dict[str, str] = {k: v[0] for k, v in _METHODS.items()}


def method_names() -> list[str]:
    """All method names, in documentation order (compositions of other symmetric methods are
    reached by name too, see :func:`get_method`)."""
    return list(_METHODS)


def _composition_name(name: str):
    from .integrators.composition import COMPOSITIONS

    for scheme in COMPOSITIONS:
        base = name[len(scheme) + 1:]
        if name.startswith(scheme + "-") and base in _METHODS and getattr(_METHODS[base][1](), "symmetric", False):
            return scheme, base
    return None


def is_method_name(name) -> bool:
    """Whether :func:`get_method` knows `name` (a listed method or a composition `"<scheme>-<method>"`)."""
    return isinstance(name, str) and (name in _METHODS or _composition_name(name) is not None)


def get_method(name: str):
    """A fresh integrator object for a method name; unknown names raise MethodError.

    Besides :func:`method_names`, `"<scheme>-<method>"` composes any symmetric method with a
    scheme of :data:`gnipy.integrators.composition.COMPOSITIONS` (e.g. `"suzuki4-gni-midpoint"`,
    `"yoshida6-mp"`)."""
    if isinstance(name, str) and name not in _METHODS and (parts := _composition_name(name)) is not None:
        return _composed(*parts)()
    if not isinstance(name, str) or name not in _METHODS:
        raise MethodError(f"method: unknown method {name!r} (known: {', '.join(_METHODS)}; compositions "
                          "'<scheme>-<symmetric method>' with scheme yoshida4, suzuki4, yoshida6, kahanli6)")
    return _METHODS[name][1]()


_SHARED: dict = {}


def shared_method(name: str):
    """The integrator of a method name, one object per name and process (:func:`get_method` makes
    a fresh one). Runs that name their method share it, and with it their checked starts and
    compiled programs (:mod:`gnipy.preparation` keys them by the method object): a repeated
    `simulate(system, "gni-midpoint", ...)` checks and dispatches nothing again. Integrators are
    immutable (equinox modules), so sharing one is safe."""
    method = _SHARED.get(name) if isinstance(name, str) else None
    if method is None:
        method = get_method(name)
        if len(_SHARED) < 256:  # names are checked by get_method; compositions' names are unbounded
            _SHARED[name] = method
    return method


def prepared_method(system, method, b0):
    """`(system, integrator)`: the system without its metadata and the method (a name or an
    Integrator) validated and prepared for it at the base point `b0`, as a run prepares them: what a
    method's one-step map is studied with (:func:`gnipy.analysis.discrete_linearization`,
    :func:`gnipy.modified_equations`). MethodError when the method does not apply to the system."""
    integrator = get_method(method) if isinstance(method, str) else method
    system = system.without_metadata()
    integrator.validate(system, b0)
    return system, integrator.prepare(system, b0)


set_method_lookup(get_method, method_names)  # the registry's default passes over methods that cannot run a system
