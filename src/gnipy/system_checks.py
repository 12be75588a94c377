"""The checks behind :meth:`gnipy.System.check`, :meth:`~gnipy.System.check_mechanical`,
:meth:`~gnipy.System.has_constant_metric` and :meth:`~gnipy.System.lagrangian_depends_on`: the
compiled evaluations of a system's values and derivatives at sample points around $b_0$ (the system
is an argument, so one compilation serves every system of a shape), and the tests of those values
(host side), each raising an :class:`~gnipy.InputError` that names the function at fault.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .compilation import jit
from .errors import InputError
from .inputs import finite_vector, flag, format_scientific, real_array, require_float64
from .spaces import Point

#: The sample points of the mechanical-type check (b0 and nearby points): fixed, so that its
#: compiled evaluation is shared by every system of a shape.
SAMPLES = 3


def check_metric(G, tol: float) -> None:
    """The metric $\\mathbb{G}(b_0)$ is finite, symmetric and positive definite (to `tol`)."""
    if not np.all(np.isfinite(G)):
        raise InputError("lagrangian: the metric d²l/dv² is not finite at q0")
    if np.max(np.abs(G - G.T)) > tol * max(1.0, np.max(np.abs(G))):
        raise InputError("lagrangian: the metric d²l/dv² is not symmetric at q0")
    eig = np.linalg.eigvalsh(G)
    if eig[0] <= tol * max(1.0, eig[-1]):
        raise InputError(
            "lagrangian: the metric d²l/dv² is not positive definite at q0 "
            f"(smallest eigenvalue {format_scientific(eig[0])})"
        )


def check_constraint_forms(mu, N: int):
    """The constraint one-forms $\\mu(b_0)$: shape (m, N) with 0 < m < N, finite, full row rank;
    returned as given."""
    if mu.ndim != 2 or mu.shape[1] != N:
        raise InputError(f"constraints: mu(q) must have shape (m, {N}), got {mu.shape}")
    if not np.all(np.isfinite(mu)):
        raise InputError("constraints: mu(q0) is not finite")
    m = mu.shape[0]
    if m == 0:
        raise InputError(
            f"constraints: mu(q0) has no rows (shape {mu.shape}); gnipy integrates constrained systems, give "
            "at least one constraint"
        )
    if m >= N:
        raise InputError(f"constraints: {m} constraints on a {N}-dimensional velocity space leave no motion")
    sv = np.linalg.svd(mu, compute_uv=False)
    if sv[-1] <= 1e-10 * max(1.0, sv[0]):
        raise InputError(
            f"constraints: mu(q0) is rank deficient (rank {int(np.sum(sv > 1e-10 * max(1.0, sv[0])))} "
            f"< {m} constraints; smallest singular value {format_scientific(sv[-1])})"
        )
    return mu


def check_affine_field(Y, N: int):
    """The affine field $Y(b_0)$: shape (N,), finite; returned as given."""
    if Y.shape != (N,):
        raise InputError(f"affine: Y(q) must have shape ({N},), got {Y.shape}")
    if not np.all(np.isfinite(Y)):
        raise InputError("affine: Y(q0) is not finite")
    return Y


def check_mechanical_type(vals: dict, samples: int, *, tol: float) -> None:
    """`l(b, v) = ½vᵀG(b)v − V(b)` at the sample points of :func:`validation_values` (`vals`, with
    the velocities `vs`): finite, no linear term in v, no mismatch with its quadratic part."""
    for i in range(samples):
        lv, G, V, lin, v = vals["lv"][i], vals["Gs"][i], vals["Vs"][i], vals["lin"][i], vals["vs"][i]
        if not np.isfinite(lv):
            raise InputError("lagrangian: l(q, v) is not finite near q0")
        quad = 0.5 * v @ G @ v - V
        scale = max(1.0, abs(lv), abs(quad))
        if np.max(np.abs(lin)) > tol * scale or abs(lv - quad) > tol * scale:
            raise InputError(
                "lagrangian: not of mechanical type ½ vᵀG(q)v − V(q) "
                f"(linear term {format_scientific(np.max(np.abs(lin)))}, "
                f"mismatch with the quadratic part {format_scientific(abs(lv - quad))})"
            )


@jit
def validation_values(system, b0, ws, vs):
    """What :meth:`gnipy.System.check` and :meth:`~gnipy.System.check_mechanical` test: l, the metric
    G and the potential at the sample points $(b_0 \\cdot w_i, v_i)$ and the linear term of l in v
    there (`lv`, `Gs`, `Vs`, `lin`), and G, μ and Y at $b_0$ (`G`, `mu`, `Y`)."""
    def at(w, v):
        b = system.space.move(b0, w)
        return dict(
            lv=system.L(b, v),
            Gs=system.metric(b),
            Vs=system.potential(b),
            lin=jax.grad(lambda u: system.L(b, u))(jnp.zeros_like(v)),
        )

    out = jax.vmap(at)(ws, vs)
    out.update(G=system.metric(b0), mu=system.mu(b0), Y=system.Y(b0))
    return out


@jit
def metric_derivatives(system, b0, ws):
    """The derivative of the metric G in the base point's local coordinates at each $b_0 \\cdot w_i$
    (exact zeros where G is constant)."""
    def one(w):
        b = system.space.move(b0, w)
        return jax.jacfwd(lambda u: system.metric(system.space.move(b, u)))(jnp.zeros(system.dim))

    return jax.vmap(one)(ws)


@jit
def lagrangian_derivatives(system, b0, ws, vs):
    """$\\partial l/\\partial w$ at $(b_0 \\cdot w_i, v_i)$, w the base point's local coordinates
    ($(x, \\xi)$ on $\\mathbb{R}^n \\times G$): exact zeros where l does not depend on them."""
    def one(w, v):
        b = system.space.move(b0, w)
        return jax.grad(lambda u: system.L(system.space.move(b, u), v))(jnp.zeros(system.dim))

    return jax.vmap(one)(ws, vs)


# ------------------------------------------------------------------------------------------------
# The checks of a System (its methods delegate here; `system` is a gnipy.System)
# ------------------------------------------------------------------------------------------------
def initial_point(system, q0, R0=None):
    """:meth:`gnipy.System.initial_point`: the validated base point of `q0` (and `R0`)."""
    x0 = finite_vector("q0", q0, system.n)
    if system.group is None:
        if R0 is not None:
            raise InputError("R0: this system has no group part")
        return jnp.asarray(x0)
    k = system.group.matrix_size
    if R0 is None:
        R = np.eye(k)  # the identity of every matrix group (NumPy: no device dispatch)
    else:
        R = real_array("R0", R0, f"a {k}x{k} group matrix")
        if R.size == k * k:
            R = R.reshape(k, k)
        if R.shape != (k, k):
            raise InputError(f"R0: expected a {k}x{k} group matrix, got shape {R.shape}")
        if not np.all(np.isfinite(R)):
            raise InputError("R0: contains NaN or infinite values")
        if not system.group.is_element(R):  # e.g. a rotation matrix on SO(3)
            raise InputError(f"R0: {system.group.why_not_element(R)}")
    return Point(jnp.asarray(x0), jnp.asarray(R))


def check_system(system, q0, v0=None, *, R0=None, project_v0: bool = False, tol: float = 1e-10):
    """:meth:`gnipy.System.check`: `(b0, v0)`, every check passed (see there)."""
    require_float64()
    project_v0 = flag("project_v0", project_v0)
    b0 = initial_point(system, q0, R0)
    if v0 is not None:
        v0 = finite_vector("v0", v0, system.dim)
    vals = validation_values_at(system, b0)
    check_mechanical_type(vals, SAMPLES, tol=1e-9)
    check_metric(vals["G"], tol)
    N = system.dim
    mu = check_constraint_forms(vals["mu"], N)
    Y = check_affine_field(vals["Y"], N)
    if system.holonomic is not None:
        check_holonomic(system, b0, tol)
    if system.force is not None:
        check_force(system, b0, np.zeros(N) if v0 is None else v0)
    if v0 is None:
        return b0, None
    res = mu @ (v0 - Y)
    scale = max(1.0, float(np.max(np.abs(v0))), float(np.max(np.abs(Y))))
    if np.max(np.abs(res)) > tol * scale:
        if not project_v0:
            raise InputError(
                "v0: the initial velocity violates the constraints mu(q0)(v0 - Y(q0)) = 0 "
                f"(residual {format_scientific(np.max(np.abs(res)))}); pass project_v0=True to project it"
            )
        v0 = np.asarray(_project_velocity(system.without_metadata(), b0, jnp.asarray(v0)))
    return b0, v0


def check_holonomic(system, b0, tol: float) -> None:
    """The initial configuration is on the holonomic constraints: $|\\varphi(b_0)| \\le$ `tol`
    (relative to $|d\\varphi|\\max(1, |x_0|)$, the size of φ's terms)."""
    from .holonomic import phi_scale

    core = system.without_metadata()
    phi = np.asarray(core.phi(b0))
    if not np.all(np.isfinite(phi)):
        raise InputError("holonomic: phi(q0) is not finite")
    scale = max(1.0, float(phi_scale(core, b0, core.holonomic_mu(b0))))
    if np.max(np.abs(phi), initial=0.0) > tol * scale:
        raise InputError(
            "q0: the initial configuration violates the holonomic constraints phi(q0) = 0 (max |phi| = "
            f"{format_scientific(np.max(np.abs(phi)))}); system.project_configuration(q0) gives the nearest "
            "configuration that satisfies them"
        )


def check_force(system, b0, v0) -> None:
    """The force at `b0`, `v0` (u = 0, t = 0) evaluates to N finite components."""
    N = system.dim
    form = f"F({', '.join(system._leading())}, v, u, t{', args' if system.force_args else ''})"
    try:
        F = np.asarray(system._call_force(*system._args(b0), jnp.asarray(v0, jnp.float64),
                                          jnp.zeros(system.inputs), jnp.asarray(0.0)))
    except Exception as e:  # the user's function failed: say where
        raise InputError(f"force: evaluating {form} failed at q0 (u = 0, t = 0): {e}") from e
    if F.size != N:
        raise InputError(f"force: {form} must return {N} components (one per velocity), got shape {F.shape}")
    if not np.all(np.isfinite(F)):
        raise InputError("force: F(q0, v0, 0, 0) is not finite")


def validation_values_at(system, b0) -> dict:
    """Everything the checks need, in one compiled evaluation (op by op, the derivatives cost
    seconds of small compilations): l, G, V and ∂l/∂v(0) at `b0` and at nearby points, and G, μ,
    Y at `b0`. A failure of the user's functions becomes an InputError."""
    rng = np.random.default_rng(0)
    N = system.dim
    ws = 0.1 * rng.standard_normal((SAMPLES, N))
    ws[0] = 0.0
    vs = rng.standard_normal((SAMPLES, N))
    try:
        out = validation_values(system.without_metadata(), b0, jnp.asarray(ws), jnp.asarray(vs))
    except InputError:
        raise
    except Exception as e:  # the user's function failed while being traced: say where
        raise InputError(f"lagrangian/constraints/affine: evaluating the system's functions failed: {e}") from e
    out = {k: np.asarray(v) for k, v in out.items()}
    out["vs"] = vs
    return out


def has_constant_metric(system, b0) -> bool:
    """:meth:`gnipy.System.has_constant_metric`."""
    rng = np.random.default_rng(1)
    ws = jnp.asarray(0.3 * rng.standard_normal((2, system.dim)))
    dG = np.asarray(metric_derivatives(system.without_metadata(), b0, ws))
    return not np.any(dG != 0.0)


def default_point(system):
    """The base point of the system's default initial condition, else of the origin (and the
    identity orientation)."""
    defaults = system.defaults or ()
    concrete = all(d is None or all(isinstance(x, float) for x in d) for d in defaults)
    x0 = defaults[0] if defaults and concrete and defaults[0] is not None else np.zeros(system.n)
    R0 = defaults[2] if len(defaults) > 2 and concrete and defaults[2] is not None else None
    try:
        return initial_point(system, np.asarray(x0), None if R0 is None else np.asarray(R0))
    except InputError:
        return initial_point(system, np.zeros(system.n))


def lagrangian_depends_on(system, part: str = "configuration") -> bool:
    """:meth:`gnipy.System.lagrangian_depends_on`."""
    if part not in ("configuration", "orientation"):
        raise InputError(f"part: expected 'configuration' or 'orientation', got {part!r}")
    if part == "orientation" and (system.group is None or not system.depends_on_orientation):
        return False
    core = system.without_metadata()
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(core)):
        return True
    rng = np.random.default_rng(2)
    ws = 0.3 * rng.standard_normal((3, system.dim))
    vs = rng.standard_normal((3, system.dim))
    with jax.ensure_compile_time_eval():  # also when called while tracing (a traced h): values known
        d = np.asarray(lagrangian_derivatives(core, default_point(system), ws, vs))
    return bool(np.any(d[:, system.n:] != 0.0 if part == "orientation" else d != 0.0))


@jit
def _project_velocity(system, b, v):
    return project_velocity(system, b, v)


def project_velocity(system, b, v):
    """$\\mathbb{G}$-orthogonal projection of v onto the affine constraint space: $P v + Q Y$."""
    from .projectors import projectors

    P, Q = projectors(system.metric(b), system.mu(b))
    return P @ v + Q @ system.Y(b)
