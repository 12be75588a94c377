"""The long runs behind the table of docs/user-guide/systems.md, "Holonomic constraints": 10⁶ steps
of the spherical pendulum (holonomic only), the sleigh with its heading on the unit circle
(holonomic and nonholonomic) and the pivoted heavy top on R³ × SO(3) (a holonomic constraint that
depends on the orientation), with the largest |φ| and the energy error in the first and the last
tenth of each run. Run: `python docs/_tools/holonomic_runs.py` (about a minute on 2 cores)."""

import numpy as np

import jax
import jax.numpy as jnp

import gnipy
from gnipy.lie_groups import SO3

jax.config.update("jax_enable_x64", True)
G = 9.81


def pendulum():
    system = gnipy.System(lambda q, v: 0.5 * v @ v - G * q[2], None, holonomic=lambda q: jnp.array([0.5 * (q @ q - 1.0)]),
                          n=3, name="spherical-pendulum")
    return system, np.array([np.sin(1.0), 0.0, -np.cos(1.0)]), np.array([0.0, 1.2, 0.0]), {}


def sleigh():
    a = 0.3
    system = gnipy.System(
        lambda q, v: 0.5 * (v[0] ** 2 + v[1] ** 2) + 0.25 * (v[2] ** 2 + v[3] ** 2),
        lambda q: jnp.stack([-q[3], q[2], a * q[3], -a * q[2]])[None],
        holonomic=lambda q: jnp.array([0.5 * (q[2] ** 2 + q[3] ** 2 - 1.0)]), n=4, name="sleigh-on-the-circle")
    return system, np.array([0.0, 0.0, 1.0, 0.0]), np.array([1.0, a, 0.0, 1.0]), {}


def top():
    inertia, c = jnp.diag(jnp.array([0.1, 0.2, 0.3])), jnp.array([0.1, 0.2, -0.5])
    system = gnipy.System(lambda x, R, v: 0.5 * v[:3] @ v[:3] + 0.5 * v[3:] @ inertia @ v[3:] - G * x[2], None,
                          holonomic=lambda x, R: x + R @ c, n=3, group=SO3(), depends_on_orientation=True,
                          name="pivoted-top")
    w0 = np.array([1.0, 0.5, 3.0])
    return system, -np.asarray(c), np.concatenate([-np.cross(w0, np.asarray(c)), w0]), {"R0": np.eye(3)}


def measure(make, method, h, steps):
    system, q0, v0, extra = make()
    sol = gnipy.simulate(system, method, q0, v0, h=h, steps=steps, save_every=max(1, steps // 10_000), throw=False,
                         **extra)
    res = np.asarray(sol.constraint_residual)
    r = len(np.asarray(system.phi(system.initial_point(q0, extra.get("R0")))))
    energy = np.asarray(sol.energy)
    err = np.abs(energy - energy[0])
    tenth = len(err) // 10
    return dict(system=system.name, method=method, h=h, steps=steps, phi=np.max(np.abs(res[:, -r:])),
                first=np.max(err[:tenth]), last=np.max(err[-tenth:]), healthy=sol.healthy)


if __name__ == "__main__":
    print("| system | method | h | steps | max abs(phi) | energy error, first tenth | last tenth | healthy |")
    print("|---|---|---|---|---|---|---|---|")
    for make, method, h in [(pendulum, "gni-trapezoid", 0.01), (pendulum, "gni-euler-a", 0.01), (pendulum, "dla", 0.01),
                            (sleigh, "gni-trapezoid", 0.01), (sleigh, "dla", 0.01),
                            (top, "gni-trapezoid", 0.01), (top, "dla", 0.01)]:
        m = measure(make, method, h, 1_000_000)
        print(f"| `{m['system']}` | `{m['method']}` | {m['h']} | 10⁶ | {m['phi']:.1e} | {m['first']:.2e} | "
              f"{m['last']:.2e} | {m['healthy']} |", flush=True)
