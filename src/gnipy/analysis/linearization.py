r"""Linear stability of a steady motion: :func:`linearize`.

A steady motion of a system on $\mathbb{R}^n$ is a motion with constant velocity $v^*$ along which
the equations do not change: $\dot v = 0$ at $(q^*, v^*)$, and every coordinate that moves
($v^*_i \ne 0$: a wheel's rotation, the position of the contact point) is one the equations do not
depend on (an ignorable coordinate). The upright bicycle or disk rolling straight at constant
speed is one; so is a rest point. Along it the linearized equations are constant (what
:func:`linearize` checks is that at the point, to first order: a coordinate that moves through a
flat point of a potential, where the equations depend on it only to second order, passes):

$$\frac{d}{dt}\begin{pmatrix}\delta q\\ \delta v\end{pmatrix} = \begin{pmatrix}0 & I\\ \partial_q a &
\partial_v a\end{pmatrix}\begin{pmatrix}\delta q\\ \delta v\end{pmatrix},$$

with $a(q, v)$ the constrained acceleration of the Lagrange–d'Alembert equations
(:func:`gnipy.equations.lagrange_dalembert_acceleration`), differentiated by JAX. gnipy writes them
on the constraint manifold as an ODE: the velocity is split into $m$ dependent components, solved
from the constraints $\mu(q)(v - Y(q)) = 0$ (the best-conditioned columns of $\mu$, by QR with
column pivoting), and $n - m$ independent ones $w$; the state is $(q, w)$. An *ignorable*
coordinate, one that no equation of the state depends on, only drifts with its perturbation (a
zero eigenvalue that tells nothing of stability): it is dropped with its equation, repeatedly
(dropping the contact point's position of a disk makes its heading ignorable too, which entered
only the contact point's velocity). The eigenvalues of what remains decide the stability; each
conserved quantity gives a zero among them, and a nonholonomic system that conserves energy has
its other eigenvalues in pairs $\pm\lambda$ (pure imaginary where the motion is stable, as the
upright disk above its critical speed: neutral, not asymptotic, stability).

:func:`stability_curve` follows a family of steady motions along a parameter (a speed) and
locates where the stability changes, as the weave and capsize speeds of a bicycle (two changes
between neighbouring samples cancel and are not seen: sample finely enough).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.optimize

from ..compilation import jit
from ..equations import lagrange_dalembert_acceleration
from ..errors import InputError
from ..inputs import finite_vector, real_number

__all__ = ["Linearization", "linearize", "DiscreteLinearization", "discrete_linearization", "StabilityCurve",
           "stability_curve", "MAP_GROWTH_TOL"]


#: eigenvalues within ZERO_TOL·max(1, ‖J‖₂) of zero are zero (and real or imaginary parts that
#: small are dropped): the zero eigenvalues left after the ignorable coordinates are removed come
#: from conserved quantities and are computed to round-off (measured on the rolling disk: ≤ 1e-15
#: with ‖J‖ ≈ 40). Limits: a genuine eigenvalue within that of zero is read as zero (a slow mode
#: beside a very stiff one: ‖J‖ mixes 1/s and 1/s²), and eigenvalues that nearly coincide (a
#: collision of two pairs) are computed only to about √ε‖J‖, so `stable` is decided to that
#: accuracy there
ZERO_TOL = 1e-10

#: a method's one-step map is stable where its growth rate (:attr:`DiscreteLinearization.growth_rate`,
#: 1/s) is at most this: the multipliers of conserved quantities and ignorable coordinates are 1,
#: computed to about √ε where they form Jordan blocks (a coordinate that drifts with its
#: perturbation), which is a growth rate of about √ε/h (measured on the Whipple bicycle at 5 m/s:
#: 1e-9 to 1e-7 /s for dla and sgni-trapezoid at h = 0.01 and 0.005)
MAP_GROWTH_TOL = 1e-5


@dataclass(frozen=True)
class Linearization:
    """The linearized equations about a steady motion (:func:`linearize`).

    Attributes:
        q, v: the steady motion's configuration and (constant) velocity.
        jacobian: the Jacobian of the equations on the constraint manifold in the state (q, w),
            w the independent velocities (n + n − m).
        state: the names of the state variables kept in `reduced` (the ignorable coordinates
            dropped).
        reduced: the Jacobian restricted to `state`: the linearized equations whose eigenvalues
            decide the stability.
        eigenvalues: the eigenvalues of `reduced`, largest real part first (within `zero_tol` of
            zero: zero; real and imaginary parts that small: dropped).
        zero_tol: :data:`ZERO_TOL` times max(1, the norm of `reduced`).
    """

    q: np.ndarray
    v: np.ndarray
    jacobian: np.ndarray
    state: tuple[str, ...]
    reduced: np.ndarray
    eigenvalues: np.ndarray
    zero_tol: float

    @property
    def zero_count(self) -> int:
        """How many eigenvalues are zero. The nonzero eigenvalues do not depend on how the state is
        chosen; this count does (which velocities are dependent, which coordinates were found
        ignorable): read it as "at least the conserved quantities left in the state", not as
        their number."""
        return int(np.sum(self.eigenvalues == 0))

    @property
    def nonzero_eigenvalues(self) -> np.ndarray:
        """The eigenvalues that are not zero, largest real part first."""
        return self.eigenvalues[self.eigenvalues != 0]

    @property
    def growth_rate(self) -> float:
        """The largest real part of the eigenvalues (0 when none is positive): > 0 for an unstable
        motion, whose perturbations grow like exp(growth_rate · t)."""
        return float(max(0.0, np.max(self.eigenvalues.real)))

    @property
    def stable(self) -> bool:
        """No eigenvalue with a positive real part: stable to first order (for a conservative system,
        neutrally: its eigenvalues are then imaginary)."""
        return bool(np.all(self.eigenvalues.real <= 0))


# Compiled, one program per system structure (Systems that differ only in `args` share it): a
# stability curve linearizes the same system at many values. Measured on the Whipple bicycle at -O0
# (the test suite's XLA flags): op by op, 22 s at the first call (each primitive of the nested
# derivatives compiled alone) and 0.25 s at each later one; compiled, 11 s once and 6 ms a call.
@jit
def _at_point(system, state):
    """The constraints' residual, the vector field (v, a) and μ at the state (q, v)."""
    n = system.n
    qq, vv = state[:n], state[n:]
    mu = system.mu(qq)
    r = mu @ vv
    if system.is_affine:
        r = r - mu @ system.Y(qq)
    return r, jnp.concatenate([vv, lagrange_dalembert_acceleration(system, qq, vv)[0]]), mu


@jit  # dep and ind: tuples of Python ints, static (part of the program)
def _reduced_jacobian(system, z, dep: tuple, ind: tuple):
    """The Jacobian of the equations on the constraint manifold in the state z = (q, w), w the
    velocities `ind` (the others, `dep`, solved from the constraints)."""
    n = system.n
    dep, ind = np.array(dep, dtype=int), np.array(ind, dtype=int)

    def full_velocity(qq, w):
        mu = system.mu(qq)
        rhs = -mu[:, ind] @ w + (mu @ system.Y(qq) if system.is_affine else 0.0)
        return jnp.zeros(n, dtype=w.dtype).at[ind].set(w).at[dep].set(jnp.linalg.solve(mu[:, dep], rhs))

    def reduced_field(zz):
        qq, w = zz[:n], zz[n:]
        vv = full_velocity(qq, w)
        return jnp.concatenate([vv, lagrange_dalembert_acceleration(system, qq, vv)[0][ind]])

    return jax.jacfwd(reduced_field)(z)


def linearize(system, q, v, *, tol: float = 1e-9) -> Linearization:
    """The linearized equations of `system` about the steady motion `(q, v)` (module docstring).

    Arguments:
        system: a System on $\\mathbb{R}^n$ (a group system's linearization is not implemented),
            without inputs; a force of q and v alone (a drag, a spring, gravity given as a load) is
            part of the equations.
        q, v: the steady motion: a configuration and a constant velocity on the constraints.
        tol: how closely the motion must be steady, relative to the size of the velocity: the
            constraints' residual and the acceleration, and the dependence of the equations on a
            coordinate that moves.

    Returns:
        A :class:`Linearization`, with the eigenvalues of the motion.

    Raises:
        InputError: when the system is not on $\\mathbb{R}^n$, has inputs or a force that depends on
            the time, or when `(q, v)` is not
            a steady motion (off the constraints, accelerating, or moving along a coordinate that
            the equations depend on), naming what fails and by how much.
    """
    if system.group is not None:
        raise InputError(f"linearize: system {system.name!r} is on R^n x G; linearize takes systems on R^n")
    if system.is_forced and system.inputs:
        raise InputError(f"linearize: system {system.name!r} has {system.inputs} input(s); a steady motion is defined "
                         f"without inputs (linearize the system without them)")
    n = system.n
    q = jnp.asarray(finite_vector("q", q, n))
    v = jnp.asarray(finite_vector("v", v, n))
    if system.is_forced:  # a force of (q, v) alone (a drag, a spring, gravity given as a load) keeps the flow autonomous
        values = [np.asarray(system.external_force_continuous(q, v, jnp.asarray(t))) for t in (0.0, 0.7, 2.9)]
        if any(np.max(np.abs(x - values[0])) > tol * (1.0 + np.max(np.abs(values[0]))) for x in values[1:]):
            raise InputError(f"linearize: system {system.name!r} has a force that depends on the time; a steady motion "
                             f"needs autonomous equations")
    scale = 1.0 + float(np.max(np.abs(v)))
    # as the driver does: without the provenance (static fields that change with the parameters'
    # values), Systems that differ only in args share the compiled pieces of the equations (a
    # stability curve over a parameter: 0.8 s per value before, 0.05 s after, measured on the sleigh)
    system = system.without_metadata()

    state = jnp.concatenate([q, v])
    off, flow, mu = (np.asarray(x) for x in _at_point(system, state))
    off = float(np.max(np.abs(off)))
    if off > tol * scale:
        raise InputError(f"linearize: (q, v) is not on the constraints: residual {off:.3g}")
    acceleration = flow[n:]
    if np.max(np.abs(acceleration)) > tol * scale:
        i = int(np.argmax(np.abs(acceleration)))
        raise InputError(f"linearize: (q, v) is not a steady motion: the velocity {system.velocities[i]!r} changes "
                         f"at rate {acceleration[i]:.3g}")
    # the equations on the constraint manifold as an ODE in (q, w), w the independent velocities
    # (the complement of the best-conditioned columns of μ at q, by QR with column pivoting)
    m = int(mu.shape[0])
    _, _, pivots = scipy.linalg.qr(mu, pivoting=True)
    dep = tuple(int(i) for i in np.sort(pivots[:m]))
    ind = tuple(int(i) for i in np.sort(pivots[m:]))
    J = np.asarray(_reduced_jacobian(system, jnp.concatenate([q, v[np.array(ind, dtype=int)]]), dep, ind))
    names = (*system.coordinates, *(system.velocities[i] for i in ind))
    # ignorable coordinates: those no kept equation depends on, dropped with their own equation
    # (their perturbation just drifts); dropping one can make another ignorable (the heading of a
    # disk enters only the velocities of its contact point)
    keep = list(range(J.shape[0]))
    small = 1e-12 * max(1.0, float(np.max(np.abs(J))))
    changed = True
    while changed:
        changed = False
        for i in [k for k in keep if k < n]:
            if np.max(np.abs(J[np.ix_(keep, [i])])) <= small and len(keep) > 1:
                keep.remove(i)
                changed = True
    moving = [i for i in range(n) if abs(float(v[i])) > tol * scale and i in keep]
    if moving:
        which = ", ".join(repr(system.coordinates[i]) for i in moving)
        raise InputError(f"linearize: (q, v) is not a steady motion: the coordinates {which} move, and the equations "
                         f"depend on them (the linearized equations would change along the motion)")
    reduced = J[np.ix_(keep, keep)]
    eigenvalues = np.linalg.eigvals(reduced)
    zero_tol = ZERO_TOL * max(1.0, float(np.linalg.norm(reduced, 2)))
    eigenvalues = np.where(np.abs(eigenvalues) <= zero_tol, 0.0, eigenvalues)
    eigenvalues = np.where(np.abs(eigenvalues.real) <= zero_tol, 1j * eigenvalues.imag, eigenvalues)
    eigenvalues = np.where(np.abs(eigenvalues.imag) <= zero_tol, eigenvalues.real + 0j, eigenvalues)
    order = np.lexsort((eigenvalues.imag, -eigenvalues.real))
    return Linearization(q=np.asarray(q), v=np.asarray(v), jacobian=J, state=tuple(names[k] for k in keep),
                         reduced=reduced, eigenvalues=eigenvalues[order], zero_tol=zero_tol)


@dataclass(frozen=True)
class DiscreteLinearization:
    """The linearized one-step map of a method about a steady motion (:func:`discrete_linearization`).

    Attributes:
        method: the method's name.
        h: the step size.
        multipliers: the eigenvalues μ of the step map's Jacobian in the method's whole state (its
            hidden state included), those of modulus below 1e-12 left out (directions the step
            forgets, e.g. a compensated sum's error term).
        exponents: log(μ)/h (principal branch): the discrete counterparts of the continuous
            eigenvalues, to which they converge at the method's order.
    """

    method: str
    h: float
    multipliers: np.ndarray
    exponents: np.ndarray

    def nearest(self, eigenvalues) -> np.ndarray:
        """For each of `eigenvalues` (the continuous ones, :attr:`Linearization.eigenvalues`), the
        exponent closest to it."""
        ev = np.atleast_1d(np.asarray(eigenvalues, dtype=complex))
        if self.exponents.size == 0:
            return np.full(ev.shape, np.nan + 0j)
        return np.array([self.exponents[np.argmin(np.abs(self.exponents - e))] for e in ev])

    @property
    def growth_rate(self) -> float:
        """The largest log|μ|/h over every multiplier, the method's parasitic ones included: > 0 where
        some perturbation grows under the method's map. On the Chaplygin sleigh sliding straight
        (stable, λ = −0.4) gni-midpoint's map has μ = −1.0408 at h = 0.1: growth +0.4, the mirror of
        the motion's contraction, carried by the GNI's hidden momentum (its map preserves volume, so
        it cannot contract without something else expanding: the methods guide, 'Where the GNI
        struggles')."""
        return float(np.max(np.log(np.abs(self.multipliers))) / self.h) if self.multipliers.size else 0.0


@jit  # h traced (one program for every step size), warmup static
def _map_jacobian(integrator, system, q, v, h, warmup: int):
    """The Jacobian of one step of `integrator` with respect to every floating-point part of its
    state, at the state `warmup` steps after its start from (q, v)."""
    state = integrator.init(system, q, v, h)
    for _ in range(warmup):
        state, _ = integrator.step(system, state, h)
    leaves, tree = jax.tree_util.tree_flatten(state)
    floating = [i for i, leaf in enumerate(leaves) if jnp.issubdtype(jnp.asarray(leaf).dtype, jnp.floating)]

    def pack(parts):
        return jnp.concatenate([jnp.ravel(jnp.asarray(parts[i])) for i in floating])

    def step(z):
        parts, offset = list(leaves), 0
        for i in floating:
            size = int(np.size(leaves[i]))
            parts[i] = z[offset:offset + size].reshape(jnp.shape(leaves[i]))
            offset += size
        new, _ = integrator.step(system, jax.tree_util.tree_unflatten(tree, parts), h)
        return pack(jax.tree_util.tree_leaves(new))

    return jax.jacfwd(step)(pack(leaves))


def discrete_linearization(system, method, q, v, h: float, *, warmup: int = 1) -> DiscreteLinearization:
    """The eigenvalues of `method`'s one-step map about the steady motion `(q, v)` with step `h`.

    The method's state at the steady motion is made as `simulate` makes it (the method's `init`)
    and then advanced by `warmup` steps, and the Jacobian of one step with respect to every
    floating-point part of that state is taken by JAX (forward mode, through the step's solves).
    The warm-up puts the state on the map's own steady motion where `init` is O(h) off it: dla
    starts from $p^+_0 = \\mathbb{G}v_0$, while its steady $p^+$ is $\\mathbb{G}v - \\tfrac h2 V_q$
    when a constraint force holds a potential (the Whipple bicycle's contact forces hold its
    weight), reached in one step; linearized at its start, an O(h) error in a multiplier μ is an
    O(1) error in log(μ)/h (measured on the bicycle at 5 m/s: exponents −13.07 and −2.74 ± 5.40i
    for the continuous −14.08 and −0.78 ± 4.46i, at h = 0.01 and 0.005 alike). A method that keeps
    the motion's stability has exponents log(μ)/h near the continuous eigenvalues, converging at its order (compare with
    :func:`linearize` through :meth:`DiscreteLinearization.nearest`); a real part of the wrong
    sign where the continuous one is 0 is numerical damping or growth.

    Arguments:
        system: the System (as for :func:`linearize`).
        method: a method's name or an :class:`~gnipy.Integrator`.
        q, v: the steady motion (checked by :func:`linearize`).
        h: the step size (> 0).
        warmup: the steps taken from the method's start before linearizing (default 1; 0
            linearizes at the start itself).

    Raises:
        InputError: as :func:`linearize`, or on a step size that is not positive or a negative
            `warmup`.
        MethodError: when the method does not apply to the system.
    """
    h = real_number("h", h, lower=0.0, strict=True)
    linearize(system, q, v)  # the same checks of the steady motion
    from ..methods import prepared_method

    q = jnp.asarray(np.asarray(q, dtype=np.float64))
    v = jnp.asarray(np.asarray(v, dtype=np.float64))
    system, integrator = prepared_method(system, method, q)
    if isinstance(warmup, bool) or not isinstance(warmup, (int, np.integer)) or warmup < 0:
        raise InputError(f"warmup: expected a non-negative integer, got {warmup!r}")
    # the map of the state alone (not of what a method keeps to make steps cheaper)
    jacobian = np.asarray(_map_jacobian(integrator.memoryless(), system, q, v, jnp.asarray(h, dtype=q.dtype),
                                        int(warmup)))
    multipliers = np.linalg.eigvals(jacobian)
    multipliers = multipliers[np.abs(multipliers) > 1e-12]
    return DiscreteLinearization(method=integrator.name, h=float(h), multipliers=multipliers,
                                 exponents=np.log(multipliers.astype(complex)) / h)


@dataclass(frozen=True)
class StabilityCurve:
    """The eigenvalues of a family of steady motions against a parameter (:func:`stability_curve`),
    as Meijaard et al. (2007, Fig. 3) plot the benchmark bicycle's against its speed.

    Attributes:
        values: the parameter's values, increasing.
        eigenvalues: (len(values), k) complex: each value's eigenvalues (:class:`Linearization`).
        growth_rate: each value's largest real part (0 where stable).
        stable: each value's stability to first order.
        transitions: the parameter values where the stability changes, each located between the
            two samples that bracket it (to `tol` relative): by Brent's method on the largest real
            part of the nonzero eigenvalues where it changes sign (asymptotically stable on one
            side), else by bisection on the stability. A real part within
            :data:`ZERO_TOL`·‖J‖ of zero counts as zero, so a transition is found where the
            crossing eigenvalue's real part is that small: off by that over the real part's slope
            (measured on the Whipple bicycle: 2e-9 m/s at the weave speed, 4e-8 m/s at the capsize
            speed, whose eigenvalue crosses slowly).
        h: the step size of the methods' maps (None without `methods`).
        method_growth: method name -> the growth rate of its one-step map at each value
            (:attr:`DiscreteLinearization.growth_rate`, its hidden state included).
    """

    values: np.ndarray
    eigenvalues: np.ndarray
    growth_rate: np.ndarray
    stable: np.ndarray
    transitions: tuple[float, ...]
    h: float | None = None
    method_growth: dict = field(default_factory=dict)

    def method_stable(self, method: str) -> np.ndarray:
        """Where `method`'s map is stable at step :attr:`h`: its growth rate at most
        :data:`MAP_GROWTH_TOL`."""
        return np.asarray(self.method_growth[method]) <= MAP_GROWTH_TOL

    def method_agrees(self, method: str) -> np.ndarray:
        """Where `method`'s map has the motion's own stability (stable where it is, unstable where
        it is not)."""
        return self.method_stable(method) == np.asarray(self.stable, dtype=bool)


def stability_curve(system, steady: Callable[[float], Sequence], values, *, tol: float = 1e-10, methods=(),
                    h: float | None = None,
                    progress: Callable[[int, int, str], None] | None = None) -> StabilityCurve:
    """Linearize a family of steady motions and find where their stability changes; with `methods`,
    also whether each method's one-step map keeps the stability (:func:`discrete_linearization`
    at each value).

    Arguments:
        system: the System (:func:`linearize`).
        steady: `steady(value) -> (q, v)`, or `(system, q, v)` where the parameter changes the
            system (`system.with_args(...)`): the steady motion at each value, e.g. the upright
            rolling at speed `value`.
        values: the parameter's values (at least two, increasing).
        tol: the relative accuracy of the transitions.
        methods: method names (or Integrators) whose one-step maps are linearized at each value,
            with step `h` (required with them).
        h: the methods' step size.
        progress: called as `progress(done, total, what)` before each linearization of a value
            (the bisections of the transitions are not counted).

    Returns:
        A :class:`StabilityCurve`; :func:`gnipy.plots.plot_stability` draws it.

    Raises:
        InputError: on values that are not increasing, a steady motion that is not one
            (:func:`linearize`, naming the value), or `methods` without a positive `h`.
        MethodError: a method that does not apply to the system.
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 1 or values.size < 2 or not np.all(np.diff(values) > 0) or not np.all(np.isfinite(values)):
        raise InputError("stability_curve: values must be at least two finite numbers, increasing")
    methods = [methods] if isinstance(methods, str) else list(methods)
    if methods:
        if h is None:
            raise InputError("h: the methods' step size is required with methods")
        h = real_number("h", h, lower=0.0, strict=True)
    total = values.size * (1 + len(methods))
    done = 0

    def tick(what: str) -> None:
        nonlocal done
        if progress is not None:
            progress(done, total, what)
        done += 1

    def motion_at(value: float):
        motion = steady(float(value))
        if not isinstance(motion, (tuple, list)) or len(motion) not in (2, 3):
            raise InputError(f"stability_curve: steady({value:.12g}) must return (q, v) or (system, q, v), "
                             f"got {type(motion).__name__}")
        return motion if len(motion) == 3 else (system, *motion)

    def at(value: float) -> Linearization:
        try:
            return linearize(*motion_at(value))
        except InputError as e:
            raise InputError(f"stability_curve: at {value:.12g}: {e}") from None

    def counted(value: float) -> Linearization:
        tick(f"{value:.6g}")
        return at(value)

    lins = [counted(x) for x in values]
    method_growth = {}
    for method in methods:
        name = method if isinstance(method, str) else method.name
        rates = []
        for x in values:
            tick(f"{name} at {x:.6g}")
            try:
                sys_, q, v = motion_at(x)
                rates.append(discrete_linearization(sys_, method, q, v, h).growth_rate)
            except InputError as e:
                raise InputError(f"stability_curve: {name} at {x:.12g}: {e}") from None
        method_growth[name] = np.array(rates)
    width = max(lin.eigenvalues.size for lin in lins)
    eig = np.full((values.size, width), np.nan + 0j)
    for i, lin in enumerate(lins):
        eig[i, :lin.eigenvalues.size] = lin.eigenvalues
    stable = np.array([lin.stable for lin in lins])
    transitions = []
    span = float(values[-1] - values[0])

    def signed(lin: Linearization) -> float:  # the largest real part of the nonzero eigenvalues
        nonzero = lin.nonzero_eigenvalues
        return float(np.max(nonzero.real)) if nonzero.size else 0.0

    for i in np.flatnonzero(stable[1:] != stable[:-1]):
        lo, hi, lo_stable = values[i], values[i + 1], stable[i]
        width = tol * max(abs(lo), abs(hi), span)  # relative to the values, and to their span at 0
        if signed(lins[i]) * signed(lins[i + 1]) < 0:
            # asymptotically stable on one side: the largest real part changes sign, a continuous
            # function of the value; Brent's method finds its zero in fewer linearizations (the
            # Whipple bicycle's weave and capsize speeds from 9 samples on [3, 7]: 29 for both,
            # against about 60 by bisection to the same tolerance)
            transitions.append(float(scipy.optimize.brentq(lambda x: signed(at(x)), lo, hi, xtol=width,
                                                           rtol=max(tol, 4 * np.finfo(float).eps))))
            continue
        for _ in range(200):  # neutrally stable on one side (real parts 0): bisection on `stable`
            if hi - lo <= width:
                break
            mid = 0.5 * (lo + hi)
            if at(mid).stable == lo_stable:
                lo = mid
            else:
                hi = mid
        transitions.append(0.5 * (lo + hi))
    return StabilityCurve(values=values, eigenvalues=eig, growth_rate=np.array([lin.growth_rate for lin in lins]),
                          stable=stable, transitions=tuple(transitions), h=None if not methods else float(h),
                          method_growth=method_growth)
