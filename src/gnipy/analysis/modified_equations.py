r"""Modified equations of a method: backward error analysis of its one-step map (the paper's open
question 1, §Conclusions).

A method's step is a map $\Phi_h$ of its own state $y$: for the GNI family the configuration and the
momentum $p^+$ it carries (so the hidden momentum is part of $y$), for `dla` $(q, p^+)$, for `mp`
$(q, v)$, for `sgni-*` and `discrete-gradient` $(q, p)$. Its Taylor expansion in the step,

$$\Phi_h(y) = y + h\,d_1(y) + h^2 d_2(y) + h^3 d_3(y) + \dots,$$

determines, term by term, the *modified vector field* $\tilde f = f_1 + h f_2 + h^2 f_3 + \dots$
whose exact flow at time h agrees with $\Phi_h$ to every order kept (Hairer, Lubich, Wanner,
*Geometric Numerical Integration*, 2nd ed., §IX.1): $f_1 = d_1$ and, for $j \ge 2$,

$$f_j = d_j - [h^j]\,\varphi_h^{F_{j-1}}(y), \qquad F_{j-1}(y, h) = \sum_{i<j} h^{i-1} f_i(y),$$

where $[h^j]$ takes the coefficient of $h^j$ and $\varphi^F_t(y) = y + \sum_{m\ge1} \frac{t^m}{m!}G_m(y)$,
$G_1 = F$, $G_{m+1} = G_m'F$, is the Taylor series of the exact flow of $F$, taken at $t = h$. $G_m$
is multilinear in F, so the coefficient is a sum over ordered $i_1, \dots, i_m < j$ with
$i_1 + \dots + i_m = j$ of $\frac{1}{m!}T(f_{i_1}, \dots, f_{i_m})$, $T(a) = a$,
$T(a_1, \dots, a_m) = T(a_1, \dots, a_{m-1})'a_m$ (forward-mode derivatives): $f_2 = d_2 - \tfrac12 f_1'f_1$,
$f_3 = d_3 - \tfrac12(f_1'f_2 + f_2'f_1) - \tfrac16(f_1'f_1)'f_1$. For a method of order p, $f_2 = \dots = f_p = 0$
and $f_1$ is the continuous vector field in the method's variables.

**The Taylor coefficients.** A step's equations are singular at $h = 0$ (a discrete Lagrangian
divides by h), so $d_j(y) = \frac{1}{j!}\partial_h^j\Phi_h(y)\big|_{h=0}$ is the limit of the exact
derivatives $\partial_h^j\Phi_h(y)$ at $h \neq 0$, which JAX computes in forward mode through the
step's Newton solves (by the implicit function theorem, :func:`gnipy.integrators.base.implicit_solve`).
They are taken at the $2M$ nodes $h = \pm\delta, \pm2\delta, \dots, \pm M\delta$ and extrapolated
to $h = 0$ by the interpolating polynomial: an error $O(\delta^{2M})$ from the extrapolation, and
round-off that grows as δ shrinks (the j-th derivative of a solve at step h loses about
$\varepsilon/h^j$). Measured on the harmonic oscillator with `gni-midpoint` ($M = 3$), the error of
$d_1, \dots, d_5$ against the closed form: 1e-4 at δ = 0.2, 3e-8 at 0.05, 1e-10 at 0.02, and at
0.01 2e-12 for $d_1$ but 1e-8 for $d_5$; the default $M = 5$, $\delta = 0.02$ (for motions whose
time scale is of order one: scale δ with it).

**The premise.** The expansion needs $\Phi_h \to \mathrm{id}$ as $h \to 0$ (:meth:`ModifiedEquations.defect`,
checked at the start). The GNI family's step tends instead to its reflection σ (Comb),
$p^+ \mapsto p^- = \bar p - (p^+ - \bar p)$: the part of $p^+$ off the constraints changes sign at
every step however small h. For it the map expanded is $\sigma\circ\Phi_h$ (σ is an involution), so
that one step is σ after the flow of $\tilde f$ for time h (:attr:`ModifiedEquations.reflected`).
States that hold a multiplier or an increment of the size of h (shake, rattle, the paper's
Euler schemes with $\lambda/h$) have no expansion as written, and are refused.

The functions are compositions of JAX derivatives, so :meth:`ModifiedEquations.field` can be
jitted and integrated by an ODE solver (each evaluation differentiates the step at the nodes:
costly, meant for small systems and for analysis).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError, MethodError

__all__ = ["ModifiedEquations", "modified_equations", "NEAR_IDENTITY"]

#: the largest |Φ₀(y) − y| relative to 1 + |y| for which a step map counts as near the identity (the
#: extrapolation's own error is far below: 1e-12 on the harmonic oscillator)
NEAR_IDENTITY = 1e-8


def _compositions(total: int, parts: int):
    """The ordered tuples of `parts` positive integers summing to `total`."""
    if parts == 1:
        yield (total,)
        return
    for first in range(1, total - parts + 2):
        for rest in _compositions(total - first, parts - 1):
            yield (first, *rest)


def _nth_derivative(f: Callable, n: int) -> Callable:
    """The n-th derivative of a function of a scalar (forward mode, nested)."""
    for _ in range(n):
        f = jax.jacfwd(f)
    return f


@dataclass(frozen=True)
class ModifiedEquations:
    """The modified vector field of a method's one-step map (:func:`modified_equations`).

    The state vector y is the method's own state without its compensated-summation errors, its
    parts in the order of :attr:`fields` and each part's arrays flattened (:attr:`sizes`: the
    lengths). On $\\mathbb{R}^n \\times G$ the base point's orientation R enters as its matrix
    entries: the step keeps R on the group, so each $f_j$'s R-part is tangent there
    ($R^{-1}f_{j,R}$ in the Lie algebra).

    Attributes:
        method: the method's name.
        order: the highest power of h kept in the field: :meth:`coefficients` returns
            $f_1, \\dots, f_{order+1}$.
        fields: the names of the state's parts in y (e.g. `("b", "p_plus")`).
        sizes: their lengths.
        delta, nodes: the extrapolation's node spacing δ and count M (nodes ±δ, …, ±Mδ).
        reflected: the map expanded is $\\sigma\\circ\\Phi_h$, the step followed by the method's
            reflection σ (the GNI family's (Comb), $p^+ \\mapsto p^-$, :meth:`~gnipy.GNI.reverse`),
            because $\\Phi_h$ itself tends to σ, not to the identity, as h → 0: then one step of the
            method is σ after the flow of the modified field for time h.
        steps: the map expanded is s steps of size h/s of the method (default 1). With s = 2 the
            GNI family's two steps tend to the identity ($\\sigma^2 = \\mathrm{id}$): the field whose
            flow for time h is two steps of h/2, the alternation of the hidden momentum averaged out.
    """

    method: str
    order: int
    fields: tuple[str, ...]
    sizes: tuple[int, ...]
    delta: float
    nodes: int
    reflected: bool
    steps: int
    _integrator: object
    _system: object
    _template: object

    def state(self, q, v, h: float, R=None) -> jax.Array:
        """The state vector y at which the method starts from `(q, v)` (and the orientation `R` on
        $\\mathbb{R}^n \\times G$, default the identity) with step `h` (its `init`). It can be traced
        (mapped over states, e.g.); traced orientations are not checked to lie on the group."""
        system = self._system
        if system.group is None:
            b = jnp.asarray(q, dtype=jnp.float64)
        elif isinstance(q, jax.core.Tracer) or isinstance(R, jax.core.Tracer):
            from ..spaces import Point

            k = system.group.matrix_size
            R = jnp.eye(k) if R is None else jnp.asarray(R, dtype=jnp.float64).reshape(k, k)
            b = Point(jnp.asarray(q, dtype=jnp.float64), R)
        else:
            b = system.initial_point(q, R)
        v = jnp.asarray(v, dtype=jnp.float64)
        return self._pack(self._integrator.init(self._system, b, v, jnp.asarray(h, dtype=v.dtype)))

    def _pack(self, state) -> jax.Array:
        return jnp.concatenate([jnp.ravel(leaf) for name in self.fields
                                for leaf in jax.tree_util.tree_leaves(getattr(state, name))])

    def _unpack(self, y):
        parts, offset = {}, 0
        for name in self.fields:
            leaves, tree = jax.tree_util.tree_flatten(getattr(self._template, name))
            new = []
            for leaf in leaves:
                size = int(np.size(leaf))
                new.append(y[offset:offset + size].reshape(jnp.shape(leaf)))
                offset += size
            parts[name] = jax.tree_util.tree_unflatten(tree, new)
        errors = {name: jax.tree_util.tree_map(jnp.zeros_like, value)
                  for name, value in self._template._asdict().items() if name not in self.fields and value is not None}
        return self._template._replace(**parts, **errors)

    def step_map(self, y, h) -> jax.Array:
        """$\\Phi_h(y)$, one step of the method from the state y (σ∘Φ_h when :attr:`reflected`; with
        :attr:`steps` = s, the s steps of size h/s that make up one step of the map)."""
        new = self._unpack(y)
        for _ in range(self.steps):
            new, _ = self._integrator.step(self._system, new, h / self.steps)
        if self.reflected:
            new = self._integrator.reverse(self._system, new)
        return self._pack(new)

    def reflect(self, y) -> jax.Array:
        """σ(y), the method's reflection (:attr:`reflected`; the identity otherwise)."""
        if not self.reflected:
            return jnp.asarray(y)
        return self._pack(self._integrator.reverse(self._system, self._unpack(jnp.asarray(y))))

    def observe(self, y):
        """`(b, v)`: the base point and the velocity the method reports at the state y (its
        `observe`, as :func:`gnipy.simulate` saves them)."""
        b, v, _ = self._integrator.observe(self._system, self._unpack(jnp.asarray(y)), self.delta)
        return b, v

    def energy(self, y) -> jax.Array:
        """The system's energy at what the method reports at y (:meth:`observe`)."""
        return self._system.energy(*self.observe(y))

    def energy_rate(self, y, j: int) -> jax.Array:
        """$\\nabla E(y)\\cdot f_j(y)$: the rate at which $f_j$ changes the energy (:meth:`energy`).
        Where the motion conserves E, $f_1$'s rate vanishes on the states the method visits, and the
        first non-zero one, $j = p + 1$, is the energy error's source at order $h^p$."""
        return jax.jvp(self.energy, (jnp.asarray(y),), (self.coefficient(j)(y),))[1]

    def base_point(self, y):
        """The base point at the head of the state vector y: q on $\\mathbb{R}^n$, the
        :class:`~gnipy.spaces.Point` $(x, R)$ on $\\mathbb{R}^n \\times G$ (R from its entries)."""
        system = self._system
        if system.group is None:
            return y[:system.n]
        k = system.group.matrix_size
        return system.space.unpack(y[:system.n + k * k])

    def configuration_velocity(self, y, f) -> jax.Array:
        """The velocity $(\\dot x, \\xi)$ in the system's coordinates that the state-space vector f
        gives the base point at y: on $\\mathbb{R}^n$ f's first n entries; on $\\mathbb{R}^n \\times G$
        ξ from f's matrix part $\\dot R$, $\\hat\\xi = R^{-1}\\dot R$ ($\\dot R R^{-1}$ for a system
        with `reconstruction="right"`)."""
        system = self._system
        n = system.n
        if system.group is None:
            return f[:n]
        k = system.group.matrix_size
        R = self.base_point(y).R
        Rdot = f[n:n + k * k].reshape(k, k)
        Rinv = system.group.inverse(R)
        X = Rdot @ Rinv if system.reconstruction == "right" else Rinv @ Rdot
        return jnp.concatenate([f[:n], system.group.vee(X)])

    def normal_part(self, y, f) -> jax.Array:
        """$\\mu(b)\\,w$, w the configuration velocity of f at y (:meth:`configuration_velocity`):
        the part off the constraint distribution, one entry per constraint row."""
        return self._system.mu(self.base_point(y)) @ self.configuration_velocity(y, f)

    def normal_velocity(self, y, j: int) -> jax.Array:
        """$\\mu(b)\\,f_{j,b}(y)$: the part of $f_j$'s configuration velocity off the constraint
        distribution at the base point (one entry per constraint row; on $\\mathbb{R}^n \\times G$
        the orientation's part as the body velocity ξ, :meth:`configuration_velocity`). Zero for
        every j ≥ 2 exactly when the modified flow's configurations keep the system's own
        constraints (and for j = 1 too where the constraints are linear)."""
        return self.normal_part(y, self.coefficient(j)(y))

    def divergence(self, y, j: int = 1) -> jax.Array:
        """$\\operatorname{div} f_j$ at y in the state's own coordinates: on $\\mathbb{R}^n$ the trace
        of $Df_j$; on $\\mathbb{R}^n \\times G$ the orientation through the chart $R e^{\\hat\\eta}$
        at η = 0 (Haar measure on G, Lebesgue on the rest): the trace of the derivative of
        $(\\dot x, \\xi, \\dot r)$ in $(x, \\eta, r)$, r the state's parts after the base point (the
        chart's own term, $\\tfrac12\\operatorname{tr}\\mathrm{ad}_\\xi$, vanishes on the unimodular
        groups SO(3) and SE(2)). A flow preserves phase volume where it is 0."""
        f = self.coefficient(j)
        system = self._system
        if system.group is None:
            return jnp.trace(jax.jacfwd(f)(y))
        n, d, k = system.n, system.group.dim, system.group.matrix_size
        R = self.base_point(y).R
        eye = jnp.eye(k, dtype=y.dtype)
        rest = y[n + k * k:]

        def chart(c):
            # the first-order curve R(I + η̂) has the derivative of R exp(η̂) at η = 0 (first derivatives only)
            step = eye + system.group.hat(c[n:n + d])
            R1 = step @ R if system.reconstruction == "right" else R @ step
            return jnp.concatenate([c[:n], R1.reshape(-1), c[n + d:]])

        def pulled(c):
            yc = chart(c)
            fc = f(yc)
            return jnp.concatenate([self.configuration_velocity(yc, fc), fc[n + k * k:]])

        c0 = jnp.concatenate([y[:n], jnp.zeros(d, dtype=y.dtype), rest])
        return jnp.trace(jax.jacfwd(pulled)(c0))

    def _extrapolated(self, y, j: int) -> jax.Array:
        """$\\partial_h^j\\Phi_h(y)$ at the nodes, extrapolated to $h = 0$ (j = 0: $\\Phi_h(y)$ itself)."""
        y = jnp.asarray(y)
        k = np.arange(1, self.nodes + 1, dtype=np.float64)
        hs = np.concatenate([-k[::-1], k]) * self.delta
        # Lagrange weights of the interpolating polynomial at h = 0
        weights = np.array([np.prod([-hs[m] / (hs[i] - hs[m]) for m in range(hs.size) if m != i])
                            for i in range(hs.size)])
        derivative = _nth_derivative(lambda h: self.step_map(y, h), j)
        # one node after another (lax.map): a vmap batches the steps' Newton loops, and such vmap graphs of
        # while loops have wedged XLA:CPU's thread pool here (0% CPU, the result never ready)
        values = jax.lax.map(derivative, jnp.asarray(hs, dtype=y.dtype))
        return jnp.tensordot(jnp.asarray(weights, dtype=y.dtype), values, axes=1)

    def taylor(self, y, j: int) -> jax.Array:
        """$d_j(y)$, the coefficient of $h^j$ in $\\Phi_h(y)$ (extrapolated from the nodes)."""
        return self._extrapolated(y, j) / math.factorial(j)

    def defect(self, y) -> jax.Array:
        """$\\max|\\Phi_0(y) - y|$, with $\\Phi_0$ the step map extrapolated to $h = 0$: zero where
        the map is near the identity, the premise of the expansion."""
        return jnp.max(jnp.abs(self._extrapolated(y, 0) - jnp.asarray(y)))

    def coefficient(self, j: int) -> Callable:
        """The function $y \\mapsto f_j(y)$."""
        if j == 1:
            return lambda y: self.taylor(y, 1)
        lower = [self.coefficient(i) for i in range(1, j)]

        def f_j(y):
            # [h^j] of the flow of F = Σ h^(i-1) f_i: Σ over m ≥ 2 and the ordered i_1..i_m < j with
            # Σ i_k = j of T_m(f_i1, …, f_im)/m!, T_1 = f_i1, T_k = T_(k-1)' f_ik (the h-degree of a
            # term is Σ(i_k − 1) = j − m, the power m comes from t^m/m! with t = h)
            flow = jnp.zeros_like(y)
            for m in range(2, j + 1):
                for parts in _compositions(j, m):
                    if max(parts) >= j:
                        continue
                    T = lower[parts[0] - 1]
                    for i in parts[1:]:
                        T = (lambda Tk, a: lambda x: jax.jvp(Tk, (x,), (a(x),))[1])(T, lower[i - 1])
                    flow = flow + T(y) / math.factorial(m)
            return self.taylor(y, j) - flow

        return f_j

    def coefficients(self, y) -> list[jax.Array]:
        """$[f_1(y), \\dots, f_{order+1}(y)]$."""
        return [self.coefficient(j)(y) for j in range(1, self.order + 2)]

    def field(self, y, h) -> jax.Array:
        """The truncated modified field $\\tilde f(y) = \\sum_{j=1}^{order+1} h^{j-1} f_j(y)$."""
        return sum(h ** (j - 1) * f for j, f in enumerate(self.coefficients(y), start=1))


def modified_equations(system, method, order: int = 2, *, q=None, v=None, R=None, delta: float = 0.02,
                       nodes: int = 5, steps: int = 1) -> ModifiedEquations:
    """The modified equations of `method` on `system` (backward error analysis of its one-step map;
    the theory and the numerical method are in :mod:`gnipy.analysis.modified_equations`).

    Arguments:
        system: a :class:`~gnipy.System` (on $\\mathbb{R}^n \\times G$ the orientation's matrix
            entries are part of the state vector).
        method: a method's name or an :class:`~gnipy.Integrator`.
        order: the highest power of h kept in the field (≥ 0): $f_1, \\dots, f_{order+1}$.
        q, v: a configuration and velocity where the method is prepared and the premise checked
            (default: the system's documented initial condition).
        R: the orientation there on $\\mathbb{R}^n \\times G$ (default the identity).
        delta, nodes: the extrapolation's node spacing δ (> 0) and count M (≥ 1).
        steps: expand s steps of size h/s as one map (:attr:`ModifiedEquations.steps`; ≥ 1).

    Returns:
        A :class:`ModifiedEquations`.

    Raises:
        InputError: on an order, δ or M out of range, or no (q, v).
        MethodError: when the method does not apply to the system, or when its step map does not tend
            to the identity at the start state (:meth:`ModifiedEquations.defect`), even after its
            reflection: no modified vector field exists there.
    """
    from ..inputs import real_number
    from ..methods import prepared_method

    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 0:
        raise InputError(f"order: expected a non-negative integer, got {order!r}")
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or nodes < 1:
        raise InputError(f"nodes: expected a positive integer, got {nodes!r}")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"steps: expected a positive integer, got {steps!r}")
    delta = real_number("delta", delta, lower=0.0, strict=True)
    if q is None or v is None:
        defaults = getattr(system, "defaults", None)
        if defaults is None:
            raise InputError("q, v: the system has no documented initial condition; give q and v")
        q = defaults[0] if q is None else q
        v = defaults[1] if v is None else v
        if R is None and len(defaults) > 2:
            R = defaults[2]
    b = system.initial_point(q, R)
    v = jnp.asarray(np.asarray(v, dtype=np.float64))
    system, integrator = prepared_method(system, method, b)
    integrator = integrator.memoryless()  # the map of the state alone (not what makes steps cheaper)
    template = integrator.init(system, b, v, jnp.asarray(delta, dtype=v.dtype))
    fields = tuple(name for name, value in template._asdict().items()
                   if value is not None and not name.endswith("_err")
                   and all(jnp.issubdtype(jnp.asarray(leaf).dtype, jnp.floating)
                           for leaf in jax.tree_util.tree_leaves(value)))
    sizes = tuple(sum(int(np.size(leaf)) for leaf in jax.tree_util.tree_leaves(getattr(template, name)))
                  for name in fields)
    defects = []
    for reflected in (False, True):
        if reflected and not callable(getattr(integrator, "reverse", None)):
            break
        result = ModifiedEquations(method=integrator.name, order=int(order), fields=fields, sizes=sizes,
                                   delta=float(delta), nodes=int(nodes), reflected=reflected, steps=int(steps),
                                   _integrator=integrator, _system=system, _template=template)
        y = result._pack(template)
        defects.append(float(jax.jit(result.defect)(y)))
        if defects[-1] <= NEAR_IDENTITY * (1.0 + float(jnp.max(jnp.abs(y)))):
            return result
    raise MethodError(
        f"method: {integrator.name}'s step map does not tend to the identity as h -> 0 at its start from "
        f"(q, v) (|Phi_0(y) - y| = {defects[0]:.3g}), nor after its reflection: its state carries a part that "
        "a step changes by O(1) however small h (a multiplier or an increment of the size of h, or a momentum "
        "that the step projects), so no modified vector field exists on its state space as it is written; "
        "the GNI family, sgni, dla, mp and discrete-gradient have one")
