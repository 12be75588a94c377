"""SymPy models shared by several test modules, written with sympy.physics.mechanics independently of
gnipy's hand-written zoo (tests/test_symbolic.py, tests/models/test_rolling_disk.py,
tests/analysis/test_linearization.py, and the user's file of tests/cli/test_stability_cli.py)."""

import sympy as sp
import sympy.physics.mechanics as me

T = me.dynamicsymbols._t


def rolling_disk_system():
    """A uniform thin disk rolling without slipping on a horizontal plane (the tilted rolling disk,
    Euler's disk without dissipation): the contact point (x, y), heading ψ, lean θ from the
    vertical and spin φ; speeds u = q̇, the contact point's two velocity components dependent."""
    x, y, psi, th, phi = q = me.dynamicsymbols("x y psi theta phi")
    u = me.dynamicsymbols("u_x u_y u_psi u_theta u_phi")
    m, R, g = sp.symbols("m R g")
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Axis", (psi, N.z))
    B = A.orientnew("B", "Axis", (th, A.x))  # B.y the disk's axis, B.z from the contact to the centre
    D = B.orientnew("D", "Axis", (phi, B.y))
    D.set_ang_vel(N, u[2] * N.z + u[3] * A.x + u[4] * B.y)
    O = me.Point("O")
    O.set_vel(N, 0)
    G = O.locatenew("C", x * N.x + y * N.y).locatenew("G", R * B.z)
    G.set_vel(N, G.pos_from(O).dt(N).subs({qi.diff(T): ui for qi, ui in zip(q, u)}))
    system = me.System(N, O)
    system.add_bodies(me.RigidBody("disk", G, D, m, (me.inertia(B, m * R ** 2 / 4, m * R ** 2 / 2, m * R ** 2 / 4), G)))
    system.q_ind, system.u_ind, system.u_dep = q, u[2:], u[:2]
    system.kdes = [ui - qi.diff(T) for qi, ui in zip(q, u)]
    slip = G.vel(N) + D.ang_vel_in(N).cross(-R * B.z)  # the velocity of the disk's material contact point
    system.add_nonholonomic_constraints(slip.dot(N.x), slip.dot(N.y))
    system.apply_uniform_gravity(-g * N.z)
    return system
