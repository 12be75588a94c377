"""`gni models` and `gni methods`: the model zoo and the methods, by name."""

from __future__ import annotations

from .app import app
from .output import console, safe

__all__ = ["methods", "models"]


@app.command()
def models():
    """List the models with their parameters (defaults), coordinate and velocity names (those of a problem
    file's [inputs] and targets) and initial condition."""
    from rich.text import Text

    import gnipy

    con = console()
    for name in gnipy.model_names():
        spec = gnipy.get_model(name)
        params = ", ".join(f"{k}={v:g}" for k, v in spec.params.items()) or "none"
        q0, v0 = spec.initial_condition(spec.params)
        extras = ["exact solution" if spec.exact is not None else None,
                  f"invariants: {', '.join(spec.invariants)}" if spec.invariants else None]
        con.print(Text.assemble((safe(name), "bold"), ": ", safe(spec.description)))
        con.print(f"    params: {params}", markup=False)
        # the velocity names too: what a problem file's [inputs] and a target's entries name
        velocities = spec.system().velocities
        con.print(f"    q = ({safe(', '.join(spec.coordinates))}), v = ({safe(', '.join(velocities))}); "
                  f"default q0 = {q0}, v0 = {v0}", markup=False)
        more = "; ".join(x for x in extras if x)
        if more:
            con.print(f"    {more}", markup=False)
        con.print(f"    default method: {spec.default_method} ({spec.default_reason})", markup=False)


@app.command()
def methods():
    """List the method names with one-line descriptions, their expected orders, and whether they
    keep holonomic constraints."""
    from rich.text import Text

    import gnipy
    from gnipy.methods import METHOD_DESCRIPTIONS

    con = console()
    width = max(len(k) for k in METHOD_DESCRIPTIONS)
    for name, desc in METHOD_DESCRIPTIONS.items():
        method = gnipy.get_method(name)
        order = method.order  # stated once, on the method
        more = f" (order {order})" if order is not None else ""
        if method.holonomic:
            more += "; keeps holonomic constraints"
        con.print(Text.assemble((f"{safe(name):<{width}}", "bold"), "  ", safe(desc + more)))
