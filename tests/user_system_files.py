"""Sources of the user's own systems, written to files by the tests (tests/test_user_systems.py,
tests/cli/test_user_systems_cli.py): the Chaplygin sleigh written as a user would, once with its
parameters as arguments (`args`) and once closed over, to compare with the zoo's own sleigh (an
independent formulation: `jax.tree_util.Partial` arguments)."""

from __future__ import annotations

import os
import textwrap

#: The sleigh with its parameters as arguments: functions at module level, `args` a dict.
SLEIGH_ARGS = textwrap.dedent('''
    """My Chaplygin sleigh (parameters as arguments)."""
    import jax.numpy as jnp

    import gnipy


    def lagrangian(q, v, p):
        return 0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * p["I"] * v[2] ** 2


    def constraints(q, p):
        th = q[2]
        return jnp.stack([-jnp.sin(th), jnp.cos(th), -p["a"] * jnp.ones_like(th)])[None, :]


    def make_sleigh(m=1.0, I=0.5, a=0.3, label="mine"):
        """A sleigh of mass m, inertia I and knife-edge offset a."""
        return gnipy.System(lagrangian, constraints, coordinates=("x", "y", "theta"), name="my-sleigh",
                            args=dict(m=m, I=I, a=a), defaults=((0.0, 0.0, 0.0), (1.0, a, 1.0)))


    def not_a_system(k=1.0):
        return 42
''')

#: The same sleigh with its parameters closed over (new functions on every call).
SLEIGH_CLOSURE = textwrap.dedent('''
    import jax.numpy as jnp

    import gnipy


    def make_sleigh(m=1.0, I=0.5, a=0.3):
        def l(q, v):
            return 0.5 * m * (v[0] ** 2 + v[1] ** 2) + 0.5 * I * v[2] ** 2

        def mu(q):
            th = q[2]
            return jnp.stack([-jnp.sin(th), jnp.cos(th), -a * jnp.ones_like(th)])[None, :]

        return gnipy.System(l, mu, coordinates=("x", "y", "theta"), name="closed-sleigh",
                            defaults=((0.0, 0.0, 0.0), (1.0, a, 1.0)))


    SLEIGH = make_sleigh()


    def needs_value(m):
        return make_sleigh(m)
''')


def write_source(path, text: str, mode: int = 0o644):
    """Write `text` to `path` with `mode` (the folder is the test's own); returns the path."""
    path.write_text(text)
    os.chmod(path, mode)
    return path
