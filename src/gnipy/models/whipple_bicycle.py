r"""The Carvallo–Whipple bicycle (Meijaard, Papadopoulos, Ruina, Schwab, *Linearized dynamics
equations for the balance and steer of a bicycle: a benchmark and review*, Proc. R. Soc. A 463
(2007) 1955–1982; "Meijaard 2007" below), written as a nonlinear gnipy System with one holonomic
constraint.

Four rigid bodies: the rear wheel R, the rear frame B (with a rigid rider), the front frame H
(handlebar and fork) and the front wheel F, hinged at the wheel axles and the steer axis; knife-edge
wheels roll without slipping on level ground. Axes as Meijaard 2007: x forward, y to the right,
z down; gravity along +z.

**Coordinates** (8): the rear contact point $(x, y)$, yaw $\psi$, roll $\phi$ (lean to the right
positive), pitch $\theta$ of the rear frame, the rear wheel's rotation $\theta_R$ (relative to the
leaning frame), steer $\delta$ (to the right positive) and the front wheel's rotation $\theta_F$
(relative to the front frame). The rear frame's orientation is $R_B = R_z(\psi)R_x(\phi)R_y(\theta)$;
the front frame turns relative to it about the steer axis, tilted back by $\lambda$ from the
vertical and passing through the ground point $(w + c, 0, 0)$ of the reference configuration
(upright, straight ahead, both contact points on the ground: rear at the origin, front at
$(w, 0, 0)$).

**Constraints.** Holonomic: the front wheel touches the ground, $z_{P_F}(\phi, \theta, \delta) = 0$,
with $P_F$ the lowest point of the front wheel (this fixes the pitch). Nonholonomic (4): the
material points of both wheels at their contact points have no horizontal velocity (the vertical
components are the derivative of the holonomic constraint and of the rear contact's height, which
the coordinates hold at 0). So the configuration space has 7 dimensions and the velocities 3
degrees of freedom (rates of roll, steer and rear wheel rotation), as Meijaard 2007 §2.

**Lagrangian** $l = \sum_i \tfrac12 m_i|\dot r_i|^2 + \tfrac12\Omega_i^TI_i\Omega_i + g\,m_i z_i$
(z down) over the four bodies, the centres' velocities and the body angular velocities
$\hat\Omega_i = R_i^T\dot R_i$ computed by forward-mode differentiation of the positions and
orientations: nothing is derived by hand beyond the geometry. The inertia tensors are Meijaard's
(Table 1), given in the reference configuration's axes.

**Benchmark.** :func:`benchmark_matrices` derives the linearized equations about the upright
straight motion at speed v, $M\ddot q + vC_1\dot q + (gK_0 + v^2K_2)q = 0$ for $q = (\phi, \delta)$,
from this nonlinear model by JAX derivatives (M from the kinetic energy on the constraints, the
others from the Jacobian of the Lagrange–d'Alembert acceleration); the tests hold them to Meijaard
2007 eq. (5.4) (:data:`PUBLISHED_MATRICES`) and derive the weave and capsize speeds.

**Nonlinear benchmark.** Basu-Mandal, Chatterjee and Papadopoulos (*Hands-free circular motions of a
benchmark bicycle*, Proc. R. Soc. A 463 (2007) 1983–2003; "Basu-Mandal 2007") give, in their Table 1,
a state of the benchmark bicycle far from upright (lean 35.6°, steer 13.2°) and the nine
accelerations their equations give there, to 13–14 digits (:data:`BASU_MANDAL_TABLE1`). Their
coordinates are another set (z up, the rear wheel's centre, lean measured from the ground plane,
the frame's pitch from the steer axis): :func:`from_basu_mandal` maps their state to this model's
$(q, \dot q)$ and :func:`basu_mandal_accelerations` maps this model's $\ddot q$ back to theirs, by
the coordinate relations of Moore's dissertation (J. K. Moore, *Human control of a bicycle*, UC
Davis 2012, Appendix: the same transformations as `dtk.bicycle.basu_to_moore_input`), with the
derivatives taken by JAX. The tests hold this model's Lagrange–d'Alembert accelerations at their
state to their table (measured: all nine within 1.3e-12 absolute, 11 significant digits or more).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..system import System

__all__ = ["BENCHMARK", "BASU_MANDAL_TABLE1", "moore_parameters", "COORDINATES", "PUBLISHED_MATRICES", "build", "upright",
           "benchmark_matrices", "contact_points", "from_basu_mandal", "basu_mandal_accelerations", "riding",
           "pushed"]

#: Meijaard 2007 Table 1: the benchmark bicycle (values exact); lam = π/10 the steer axis tilt
BENCHMARK = {
    "w": 1.02, "c": 0.08, "lam": math.pi / 10, "g": 9.81,
    "rR": 0.3, "mR": 2.0, "IRxx": 0.0603, "IRyy": 0.12,
    "xB": 0.3, "zB": -0.9, "mB": 85.0, "IBxx": 9.2, "IByy": 11.0, "IBzz": 2.8, "IBxz": 2.4,
    "xH": 0.9, "zH": -0.7, "mH": 4.0, "IHxx": 0.05892, "IHyy": 0.06, "IHzz": 0.00708, "IHxz": -0.00756,
    "rF": 0.35, "mF": 3.0, "IFxx": 0.1405, "IFyy": 0.28,
}

#: Meijaard 2007 eq. (5.4): the benchmark's linearized equations' matrices (14 digits)
PUBLISHED_MATRICES = {
    "M": ((80.81722, 2.31941332208709), (2.31941332208709, 0.29784188199686)),
    "C1": ((0.0, 33.86641391492494), (-0.85035641456978, 1.68540397397560)),
    "K0": ((-80.95, -2.59951685249872), (-2.59951685249872, -0.80329488458618)),
    "K2": ((0.0, 76.59734589573222), (0.0, 2.65431523794604)),
}

#: Basu-Mandal 2007 Table 1, in their coordinates (x, y, z the rear wheel's centre, z up; θ yaw, ψ lean
#: from the ground, φ pitch, ψ_f steer, β_r and β_f the wheels' rotations): the state ("q", "qdot")
#: and the accelerations ("qddot") their equations give for the benchmark bicycle, as published
BASU_MANDAL_TABLE1 = {
    "names": ("x", "y", "z", "theta", "psi", "phi", "psi_f", "beta_r", "beta_f"),
    "q": (0.0, 0.0, 0.2440472102925, 0.0, 0.9501292851472, 3.1257073014894, 0.2311385135743, 0.0, 0.0),
    "qdot": (-2.8069345714545, -0.1480982396001, 0.1058778746261, 0.7830033527065, 0.6068425835418,
             -0.0119185528069, 0.4859824687093, 8.9129896614890, 8.0133620584155),
    "qddot": (-0.5041626315047, -0.3449706619454, -1.4604528332980, 0.8353281706379, -7.8555281128244,
              0.1205543897884, -4.6198904039403, 1.8472554144217, 2.4548072904550),
}

COORDINATES = ("x", "y", "yaw", "roll", "pitch", "rear_wheel", "steer", "front_wheel")
_ROLL, _PITCH, _REAR, _STEER, _FRONT = 3, 4, 5, 6, 7


def _mm(A, B):
    """The product of 3×3 matrices (or of a 3×3 matrix and a vector) as elementwise products and a
    sum, not an XLA dot: on the CPU each small dot is a library call of its own, and a step's
    derivatives of these products multiply them. Measured on the dla step (XLA, 2-core Xeon, the
    pushed upright motion at 5 m/s, h = 0.01, the final state saved): 771 µs a step with `@` and
    einsum, 192 µs with these; the same bicycle converted from SymBRiM's SymPy expressions by
    :func:`gnipy.from_sympy` takes 95 µs."""
    if B.ndim == 1:
        return jnp.sum(A * B[None, :], axis=1)
    return jnp.sum(A[:, :, None] * B[None, :, :], axis=1)


def _rx(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _about(axis, a):
    """The rotation by `a` about the unit vector `axis` (Rodrigues)."""
    K = jnp.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return jnp.eye(3) + jnp.sin(a) * K + (1.0 - jnp.cos(a)) * _mm(K, K)


def _inertia(xx, yy, zz, xz):
    return jnp.array([[xx, 0.0, xz], [0.0, yy, 0.0], [xz, 0.0, zz]])


def _bodies(q, p):
    """The four bodies' centres, orientations, and the wheels' centres and contact points:
    `(centres (4, 3), rotations (4, 3, 3), (C_R, P_R, C_F, P_F))`, bodies in the order R, B, H, F."""
    x, y, psi, phi, theta, th_r, delta, th_f = (q[i] for i in range(8))
    lean = _mm(_rz(psi), _rx(phi))
    RB = _mm(lean, _ry(theta))
    P_R = jnp.stack([x, y, jnp.zeros_like(x)])
    C_R = P_R - p["rR"] * lean[:, 2]  # the rear wheel's centre, rR above the contact in its plane
    axis = jnp.stack([jnp.sin(p["lam"]), 0.0 * p["lam"], jnp.cos(p["lam"])])  # the steer axis, downward
    a0 = jnp.stack([p["w"] + p["c"], 0.0 * p["w"], p["rR"]])  # its ground point, from the rear centre (body)
    Rs = _about(axis, delta)
    RH = _mm(RB, Rs)

    def front(point):  # a point of the front frame given in the reference configuration (body coords)
        return C_R + _mm(RB, a0 + _mm(Rs, point - a0))

    C_B = C_R + _mm(RB, jnp.stack([p["xB"], 0.0 * p["xB"], p["zB"] + p["rR"]]))
    C_H = front(jnp.stack([p["xH"], 0.0 * p["xH"], p["zH"] + p["rR"]]))
    C_F = front(jnp.stack([p["w"], 0.0 * p["w"], p["rR"] - p["rF"]]))
    n = RH[:, 1]  # the front axle
    down = jnp.array([0.0, 0.0, 1.0]) - n[2] * n
    P_F = C_F + p["rF"] * down / jnp.sqrt(jnp.sum(down * down))  # the front wheel's lowest point
    rotations = jnp.stack([_mm(lean, _ry(th_r)), RB, RH, _mm(RH, _ry(th_f))])
    return jnp.stack([C_R, C_B, C_H, C_F]), rotations, (C_R, P_R, C_F, P_F)


def contact_points(q, p):
    """The rear and front contact points (3,) at the configuration `q` (the front one's height is
    the holonomic constraint)."""
    _, _, (_, P_R, _, P_F) = _bodies(q, p)
    return P_R, P_F


def _motion(q, v, p):
    """The bodies' centres, rotations and their derivatives along the velocity `v`."""
    return jax.jvp(lambda qq: _bodies(qq, p), (q,), (v,))


def _lagrangian(q, v, p):
    (centres, rotations, _), (dcentres, drotations, _) = _motion(q, v, p)
    masses = jnp.stack([p["mR"], p["mB"], p["mH"], p["mF"]])
    inertias = jnp.stack([
        _inertia(p["IRxx"], p["IRyy"], p["IRxx"], 0.0 * p["IRxx"]),
        _inertia(p["IBxx"], p["IByy"], p["IBzz"], p["IBxz"]),
        _inertia(p["IHxx"], p["IHyy"], p["IHzz"], p["IHxz"]),
        _inertia(p["IFxx"], p["IFyy"], p["IFxx"], 0.0 * p["IFxx"]),
    ])
    omega_hat = jnp.sum(rotations[:, :, :, None] * drotations[:, :, None, :], axis=1)  # Rᵀ Ṙ, skew
    omega = jnp.stack([omega_hat[:, 2, 1], omega_hat[:, 0, 2], omega_hat[:, 1, 0]], axis=1)
    kinetic = 0.5 * jnp.sum(masses * jnp.sum(dcentres**2, axis=1)) + 0.5 * jnp.sum(omega[:, :, None] * inertias * omega[:, None, :])
    return kinetic + p["g"] * jnp.sum(masses * centres[:, 2])  # V = −g Σ m z (z down)


def _contact_velocities(q, v, p):
    """The horizontal velocities of the wheels' material points at their contact points (4,)."""
    (_, rotations, (C_R, P_R, C_F, P_F)), (_, drotations, (dC_R, _, dC_F, _)) = _motion(q, v, p)

    def spin(R, dR):  # the angular velocity in space: (Ṙ Rᵀ)^vee
        W = jnp.sum(dR[:, None, :] * R[None, :, :], axis=2)  # Ṙ Rᵀ
        return jnp.stack([W[2, 1], W[0, 2], W[1, 0]])

    rear = dC_R + jnp.cross(spin(rotations[0], drotations[0]), P_R - C_R)
    front = dC_F + jnp.cross(spin(rotations[3], drotations[3]), P_F - C_F)
    return jnp.concatenate([rear[:2], front[:2]])


def _constraints(q, p):
    return jax.jacfwd(lambda v: _contact_velocities(q, v, p))(jnp.zeros(8, dtype=q.dtype))


def _holonomic(q, p):
    return contact_points(q, p)[1][2:3]


def build(params: dict | None = None, *, defaults=None) -> System:
    """The Whipple bicycle as a System on R⁸ with the parameters `params` (default
    :data:`BENCHMARK`; a partial dict updates it), named parameters as `args`; `defaults` its
    default initial condition `(q0, v0)` (None: at rest)."""
    p = dict(BENCHMARK)
    p.update(params or {})
    return System(_lagrangian, _constraints, holonomic=_holonomic, coordinates=COORDINATES, name="whipple-bicycle",
                  args={k: float(v) for k, v in p.items()}, defaults=defaults)


def riding(v: float = 5.0) -> System:
    """The benchmark bicycle riding upright and straight at the forward speed `v` (m/s): its
    default initial condition is that steady motion (:func:`upright`). As a model reference,
    `gnipy.models.whipple_bicycle:riding`, it is what `gni stability` and `gni run` take:

        gni stability gnipy.models.whipple_bicycle:riding --over v=0:10:41 --out bicycle/

    draws the eigenvalues against the speed (Meijaard 2007 Fig. 3) with the weave and capsize speeds."""
    return build(defaults=upright(None, v))


def pushed(v: float = 5.0, roll_rate: float = 0.5) -> System:
    """The benchmark bicycle riding upright and straight at the forward speed `v` (m/s), pushed into
    the roll rate `roll_rate` (rad/s): its default initial condition is that state, the velocity
    projected onto the constraints. At 5 m/s (inside the self-stable speed range, Meijaard 2007) the
    weave that the push starts decays. As a model reference, `gnipy.models.whipple_bicycle:pushed`
    is what `gni run`, `gni atlas` and `gni convergence` take."""
    q0, v0 = upright(None, v)
    v0 = v0.copy()
    v0[_ROLL] = roll_rate
    bicycle = build()
    _, v0 = bicycle.check(q0, v0, project_v0=True)
    return build(defaults=(q0, np.asarray(v0)))


def upright(params: dict | None, v: float):
    """The upright, straight steady motion at forward speed `v`: `(q, qdot)` (the wheels turning
    at −v/r about their axles, which point to the right)."""
    p = dict(BENCHMARK)
    p.update(params or {})
    qdot = np.zeros(8)
    qdot[0], qdot[_REAR], qdot[_FRONT] = v, -v / p["rR"], -v / p["rF"]
    return np.zeros(8), qdot


def benchmark_matrices(system: System):
    """`{"M", "C1", "K0", "K2"}`: the 2×2 matrices of the linearized equations of roll and steer
    about the upright straight motion, $M\\ddot q + vC_1\\dot q + (gK_0 + v^2K_2)q = 0$ (Meijaard
    2007 eq. (2.12)), derived from the nonlinear `system` (built by :func:`build`) by JAX:

    - the pitch $\\theta(\\phi, \\delta)$ from the holonomic constraint (Newton's method), and the
      dependent velocities from the constraints given $(\\dot\\phi, \\dot\\delta)$ and the rear
      wheel's rate $-v/r_R$;
    - $M$: the Hessian of the kinetic energy in $(\\dot\\phi, \\dot\\delta)$ at rest;
    - from the Jacobian of the constrained acceleration $(\\ddot\\phi, \\ddot\\delta)$ of the
      Lagrange–d'Alembert equations (:func:`gnipy.equations.lagrange_dalembert_acceleration`) in
      $(\\phi, \\delta)$ and $(\\dot\\phi, \\dot\\delta)$: $gK_0 = -MJ_q(0)$,
      $K_2 = -MJ_q(1) - gK_0$ and $C_1 = -MJ_{\\dot q}(1)$ (the equations are exactly linear in v and
      quadratic in v²: the speeds 0 and 1 give them to round-off).
    """
    out = _benchmark_matrices(system.without_metadata())
    return {k: np.asarray(x) for k, x in out.items()}


@jit
def _benchmark_matrices(core):
    from ..equations import lagrange_dalembert_acceleration

    p = core.args

    def configuration(s):
        def pitch_step(theta, _):
            q = jnp.zeros(8).at[_ROLL].set(s[0]).at[_STEER].set(s[1]).at[_PITCH].set(theta)
            f = lambda t: _holonomic(q.at[_PITCH].set(t), p)[0]  # noqa: E731
            return theta - f(theta) / jax.grad(f)(theta), None

        theta, _ = jax.lax.scan(pitch_step, jnp.zeros(()), None, length=12)
        return jnp.zeros(8).at[_ROLL].set(s[0]).at[_STEER].set(s[1]).at[_PITCH].set(theta)

    free = jnp.array([_ROLL, _STEER, _REAR])
    dependent = jnp.array([i for i in range(8) if i not in (_ROLL, _STEER, _REAR)])

    def velocity(q, rates, v):
        mu = core.mu(q)  # the nonholonomic rows and dφ
        given = jnp.zeros(8).at[free].set(jnp.stack([rates[0], rates[1], -v / p["rR"]]))
        dep = jnp.linalg.solve(mu[:, dependent], -mu @ given)
        return given.at[dependent].set(dep)

    def acceleration(state, v):
        s, rates = state[:2], state[2:]
        q = configuration(s)
        a, _ = lagrange_dalembert_acceleration(core, q, velocity(q, rates, v))
        return jnp.stack([a[_ROLL], a[_STEER]])

    def kinetic(rates):
        q = configuration(jnp.zeros(2))
        qd = velocity(q, rates, 0.0)
        return core.L(q, qd) + core.potential(q)

    M = jax.hessian(kinetic)(jnp.zeros(2))
    # one derivative program for both speeds (vmapped): it is most of the compilation
    J0, J1 = jax.vmap(lambda v: jax.jacfwd(acceleration)(jnp.zeros(4), v))(jnp.array([0.0, 1.0]))
    gK0 = -M @ J0[:, :2]
    K0 = gK0 / p["g"]
    K2 = -M @ J1[:, :2] - gK0
    C1 = -M @ J1[:, 2:]
    return {"M": M, "C1": C1, "K0": K0, "K2": K2}


def moore_parameters(params: dict | None = None) -> dict[str, float]:
    """The benchmark's parameters (`params` over :data:`BENCHMARK`) in Moore's set, as SymBRiM's
    Whipple bicycle names them (`rear_frame_d1`, `front_frame_l4`, ...; J. K. Moore, *Human control
    of a bicycle*, UC Davis 2012: the relations of `dtk.bicycle.benchmark_to_moore`), the frames'
    inertia rotated by the steer axis tilt λ. Checked by SymBRiM's bicycle reproducing Basu-Mandal's
    Table 1 (tests/test_symbolic.py)."""
    b = dict(BENCHMARK)
    b.update(params or {})
    lam = b["lam"]
    c, s = math.cos(lam), math.sin(lam)
    d1 = c * (b["c"] + b["w"] - b["rR"] * math.tan(lam))
    d3 = -c * (b["c"] - b["rF"] * math.tan(lam))
    l4 = (b["zH"] + b["rF"]) * c + (b["xH"] - b["w"]) * s
    rot = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    IB = rot @ np.array([[b["IBxx"], 0, b["IBxz"]], [0, b["IByy"], 0], [b["IBxz"], 0, b["IBzz"]]]) @ rot.T
    IH = rot @ np.array([[b["IHxx"], 0, b["IHxz"]], [0, b["IHyy"], 0], [b["IHxz"], 0, b["IHzz"]]]) @ rot.T
    values = {
        "rear_frame_body_mass": b["mB"], "rear_frame_ixx": IB[0, 0], "rear_frame_iyy": IB[1, 1],
        "rear_frame_izz": IB[2, 2], "rear_frame_izx": IB[2, 0], "rear_frame_d1": d1,
        "rear_frame_l1": b["xB"] * c - b["zB"] * s - b["rR"] * s, "rear_frame_l2": b["xB"] * s + b["zB"] * c + b["rR"] * c,
        "front_frame_body_mass": b["mH"], "front_frame_ixx": IH[0, 0], "front_frame_iyy": IH[1, 1],
        "front_frame_izz": IH[2, 2], "front_frame_izx": IH[2, 0], "front_frame_d3": d3,
        "front_frame_d2": (b["rR"] + d1 * s - b["rF"] + d3 * s) / c,
        "front_frame_l3": (b["xH"] - b["w"] - l4 * s) / c, "front_frame_l4": l4,
        "rear_wheel_mass": b["mR"], "rear_wheel_ixx": b["IRxx"], "rear_wheel_iyy": b["IRyy"], "rear_wheel_r": b["rR"],
        "front_wheel_mass": b["mF"], "front_wheel_ixx": b["IFxx"], "front_wheel_iyy": b["IFyy"], "front_wheel_r": b["rF"],
        "g": b["g"],
    }
    return {k: float(v) for k, v in values.items()}


def _basu_mandal_coordinates(q, p):
    """Basu-Mandal 2007's nine coordinates of the configuration `q` of this model (Moore 2012's
    relations; this model's pitch is Moore's minus λ, its rear wheel angle is taken from the
    yaw–roll frame where Moore's is from the rear frame)."""
    x, y, yaw, roll, pitch, th_r, steer, th_f = (q[i] for i in range(8))
    rr = p["rR"]
    return jnp.stack([
        rr * jnp.sin(yaw) * jnp.sin(roll) - x,
        rr * jnp.cos(yaw) * jnp.sin(roll) + y,
        rr * jnp.cos(roll),
        -yaw,
        jnp.pi / 2 - roll,
        jnp.pi - pitch,
        -steer,
        -(th_r - pitch),
        -th_f,
    ])


def from_basu_mandal(q, qdot, params: dict | None = None):
    """This model's `(q, qdot)` (arrays (8,)) at the state `q`, `qdot` written in Basu-Mandal 2007's
    coordinates (:data:`BASU_MANDAL_TABLE1`'s order; the rear wheel's angle is taken as its
    β_r). The velocities are the least-squares solution of the nine relations (one is redundant:
    ż follows from the lean rate)."""
    p = dict(BENCHMARK)
    p.update(params or {})
    b = np.asarray(q, dtype=float)
    rr = p["rR"]
    yaw, roll, pitch = -b[3], np.pi / 2 - b[4], np.pi - b[5]
    ours = np.array([rr * np.sin(yaw) * np.sin(roll) - b[0], b[1] - rr * np.cos(yaw) * np.sin(roll), yaw, roll,
                     pitch, pitch - b[7], -b[6], -b[8]])
    J = np.asarray(jax.jacfwd(lambda qq: _basu_mandal_coordinates(qq, p))(jnp.asarray(ours)))
    qdot_ours, *_ = np.linalg.lstsq(J, np.asarray(qdot, dtype=float), rcond=None)
    return ours, qdot_ours


def basu_mandal_accelerations(q, qdot, qddot, params: dict | None = None):
    """The second derivatives of Basu-Mandal 2007's nine coordinates along a motion of this model
    through `q` with velocity `qdot` and acceleration `qddot` (arrays (8,)): J q̈ + (dJ q̇) q̇, by
    JAX's forward mode."""
    p = dict(BENCHMARK)
    p.update(params or {})

    def velocity(qq, vv):
        return jax.jvp(lambda x: _basu_mandal_coordinates(x, p), (qq,), (vv,))[1]

    q, qdot, qddot = (jnp.asarray(a, dtype=float) for a in (q, qdot, qddot))
    return np.asarray(jax.jvp(velocity, (q, qdot), (qdot, qddot))[1])
