"""Nonholonomic mechanical systems: a Lagrangian, constraint one-forms and an affine part.

A :class:`System` holds the user's data, on $Q = \\mathbb{R}^n$ or on
$Q = \\mathbb{R}^n \\times G$ with velocities $v = (\\dot x, \\xi)$ in left trivialization:

- a Lagrangian of mechanical type $l(b, v) = \\tfrac12 v^T \\mathbb{G}(b) v - V(b)$,
- constraint one-forms $\\mu(b)$ ($m \\times N$, full row rank),
- an optional affine vector field $Y(b)$; the constraints are $\\mu(b)(v - Y(b)) = 0$;
- optional holonomic constraints $\\varphi(b) = 0$ (r of them), whose differentials $d\\varphi(b)$
  join $\\mu$ as velocity constraints (:mod:`gnipy.holonomic`);
- an optional generalized force $F(b, v, u, t)$ with inputs u (:mod:`gnipy.forcing`).

On $\\mathbb{R}^n \\times G$ the system is *reduced* (paper §7) when l, μ, Y do not depend on the
orientation R (the user's functions take `(x, v)`, `(x)`), and of *Lie groupoid* type (paper §9)
when they do (`depends_on_orientation=True`; the functions take `(x, R, v)`, `(x, R)`).

Everything else (metric, potential, momenta, projectors, $\\Pi = \\mathbb{G} Y$) is derived by
automatic differentiation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .compilation import traced_once
from . import system_checks as checks
from .errors import InputError
from .system_arguments import (check_functions, configuration_space, dimension, inputs_count, provenance,
                               scalar_args, system_args, takes_args_last, velocity_names)
from .system_checks import check_mechanical_type, project_velocity  # noqa: F401 - imported from here

__all__ = ["System"]


class System(eqx.Module):
    """A nonholonomic mechanical system on $\\mathbb{R}^n$ or on $\\mathbb{R}^n \\times G$.

    Arguments:
        lagrangian: the Lagrangian, of mechanical type (quadratic in `v`, no linear term):
            `l(q, v)` on $\\mathbb{R}^n$; `l(x, v)` for a reduced system on $\\mathbb{R}^n \\times G$;
            `l(x, R, v)` when `depends_on_orientation=True`. On $\\mathbb{R}^n \\times G$,
            $v = (\\dot x, \\xi)$ with $\\xi = R^{-1}\\dot R$ in the group's `vee` coordinates.
        constraints: the constraint one-forms as rows, `mu(q)` / `mu(x)` / `mu(x, R)` -> (m, N);
            may be None when `holonomic` is given (a system with holonomic constraints only).
        affine: optional `Y(q)` / `Y(x)` / `Y(x, R)` -> (N,); the constraints are $\\mu(v - Y) = 0$.
        holonomic: optional holonomic constraints `phi(q)` / `phi(x)` / `phi(x, R)` -> (r,): the
            motion stays on $\\varphi = 0$. Their differentials $d\\varphi$ are appended to the rows
            of :meth:`mu` (the velocity constraints $d\\varphi\\,v = 0$), and the methods that
            support them (:data:`gnipy.holonomic.HOLONOMIC_METHODS`) keep $\\varphi(q_k) = 0$ to
            round-off with a position multiplier (:mod:`gnipy.holonomic`); the others refuse such a
            system.
        n: dimension of the Euclidean factor (inferred from `coordinates` if omitted; may be 0
            when a group is given).
        group: a Lie group from :mod:`gnipy.lie_groups` (e.g. `SO3()`), or None for $\\mathbb{R}^n$.
        retraction: `"cayley"` (default) or `"exp"`, or a retraction object: how steps move on G.
        depends_on_orientation: the functions take R (the Lie groupoid case of paper §9).
        reconstruction: how a *reduced* system's orientation follows from its group velocity ξ:
            `"left"` (default) reads ξ as the body velocity, $\\dot R = R\\hat\\xi$ and
            $R_{k+1} = R_k\\tau(\\sigma_k)$; `"right"` as the space velocity, $\\dot R = \\hat\\xi R$ and
            $R_{k+1} = \\tau(\\sigma_k)R_k$ (e.g. the rolling ball of paper §7.4, whose constraints hold
            for the space angular velocity). The equations of $(x, \\xi)$ are the same either way;
            only R differs (:class:`~gnipy.spaces.GroupSpace`). Systems that depend on R need
            `"left"`.
        orientation_note: a sentence on what R means for this system, appended to the file
            attribute `orientation` (:attr:`orientation_description`), e.g. that it is not a
            physical attitude for these parameters.
        coordinates: names of the coordinates x (default `q0, q1, ...`).
        velocities: names of the N velocity components (default `d<coordinate>` then the group's).
        name: a short name used in reports and files.
        params: parameters of the system, for provenance (a dict of floats; default: the scalar
            entries of `args`).
        defaults: optional default initial condition `(q0, v0)` or `(q0, v0, R0)`.
        force: optional generalized force `F(q, v, u, t)` / `F(x, v, u, t)` / `F(x, R, v, u, t)`
            -> (N,), a covector in the velocity coordinates (on $\\mathbb{R}^n\\times G$ its group
            part pairs with ξ: a body torque for `reconstruction="left"`, a space torque for
            `"right"`); `u` the inputs (a vector of length `inputs`, empty when there are none),
            `t` the time. See :mod:`gnipy.forcing` for how the methods discretize it.
        inputs: the number m of inputs u (given to :func:`gnipy.simulate` as `controls=`).
        args: named parameters that every function receives as its last argument (as diffrax's
            `args`): `l(q, v, args)`, `mu(q, args)`, `Y(q, args)`, `F(q, v, u, t, args)` (on
            $\\mathbb{R}^n \\times G$ after the same leading arguments as above), with `args` a dict of
            float64 arrays, e.g. `args["m"]`. They are pytree leaves of the System: `jax.grad`
            reaches them (:meth:`with_args`), systems that differ only in them share one
            compilation and run as one batch, and sweeps, `fit` and control set them by name.
            Default None: the functions take no such argument (parameters closed over, or as
            `jax.tree_util.Partial` arguments, keep working).

    Raises:
        InputError: on inconsistent dimensions or names.
    """

    lagrangian: Callable[..., Any]
    constraints: Callable[..., Any] | None
    affine: Callable[..., Any] | None
    space: Any
    depends_on_orientation: bool = eqx.field(static=True)
    coordinates: tuple[str, ...] = eqx.field(static=True)
    velocities: tuple[str, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True)
    #: the zoo model this system was built as (:meth:`as_model`), None for a System written by hand
    #: whatever its `name`: the model's registered invariants and measured default method apply
    #: to the systems the zoo builds only
    model: str | None = eqx.field(static=True)
    #: for a user's system loaded by reference (:mod:`gnipy.user_systems`), `(reference, digest)`:
    #: how to rebuild it and the SHA-256 of its source, recorded by streamed runs and sweeps; None
    #: otherwise
    origin: tuple[str, str | None] | None = eqx.field(static=True)
    params: tuple[tuple[str, float], ...] = eqx.field(static=True)
    defaults: tuple | None = eqx.field(static=True)
    orientation_note: str = eqx.field(static=True)
    force: Callable[..., Any] | None
    drive: Any
    inputs: int = eqx.field(static=True)
    #: for the systems a model builds (the zoo's, a user's function), how to build the system again
    #: from the named parameters' values: `rebuild(values) -> System | None` (None: it cannot), so
    #: that :meth:`with_args` keeps the default initial condition of the new values; None otherwise
    rebuild: Callable[..., Any] | None = eqx.field(static=True, default=None)
    #: whether the force receives :attr:`args` last: as every function does when given to the
    #: constructor; a force added by :meth:`with_force`, when it takes one more argument
    force_args: bool = eqx.field(static=True, default=False)
    #: the named parameters the functions receive as their last argument (a dict of float64
    #: arrays, pytree leaves), or None for functions that take none (their parameters closed over)
    args: Any = None
    #: the holonomic constraints $\\varphi$ (see the constructor), or None
    holonomic: Callable[..., Any] | None = None

    def __init__(
        self,
        lagrangian: Callable[..., Any],
        constraints: Callable[..., Any],
        affine: Callable[..., Any] | None = None,
        *,
        holonomic: Callable[..., Any] | None = None,
        n: int | None = None,
        group=None,
        retraction="cayley",
        depends_on_orientation: bool = False,
        reconstruction: str = "left",
        coordinates: Sequence[str] | None = None,
        velocities: Sequence[str] | None = None,
        name: str = "system",
        params: dict[str, float] | None = None,
        defaults: tuple | None = None,
        orientation_note: str | None = None,
        force: Callable[..., Any] | None = None,
        inputs: int = 0,
        args: Any = None,
    ):
        check_functions(lagrangian, constraints, affine, force, holonomic)
        n, coordinates = dimension(n, coordinates, group)
        space, group_names = configuration_space(n, group, retraction, depends_on_orientation, reconstruction)
        self.lagrangian = lagrangian
        self.constraints = constraints
        self.affine = affine
        self.holonomic = holonomic
        self.space = space
        self.depends_on_orientation = bool(depends_on_orientation)
        self.coordinates = coordinates
        self.velocities = velocity_names(velocities, coordinates, group_names, space.dim)
        self.name = str(name)
        self.model = None
        self.origin = None
        self.rebuild = None
        self.args = system_args(args)
        self.force_args = self.args is not None and force is not None
        if params is None and self.args is not None:
            params = scalar_args(self.args)
        self.params, self.defaults = provenance(params, defaults)
        self.orientation_note = "" if orientation_note is None else str(orientation_note)
        self.inputs = inputs_count(force, inputs)
        from .forcing import Drive

        self.force = force
        self.drive = None if force is None else Drive.make(inputs=self.inputs)

    # ----------------------------------------------------------------------------------------
    # Evaluating the user's functions at a base point b (q on R^n, Point(x, R) on R^n x G)
    # ----------------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Dimension of the Euclidean factor (of the whole configuration space on $\\mathbb{R}^n$)."""
        return self.space.n

    @property
    def dim(self) -> int:
        """Dimension N of the velocity space ($n$ plus the dimension of the Lie algebra)."""
        return self.space.dim

    @property
    def group(self):
        """The Lie group G, or None on $\\mathbb{R}^n$."""
        return getattr(self.space, "group", None)

    @property
    def reconstruction(self) -> str | None:
        """`"left"` or `"right"`: how R follows from the group velocity (see the constructor); None
        on $\\mathbb{R}^n$."""
        return getattr(self.space, "reconstruction", None)

    @property
    def orientation_description(self) -> str:
        """What the orientations R of a solution are, as one sentence (the file attribute
        `orientation`): the velocity they are reconstructed from and how, plus the system's
        `orientation_note`; empty on $\\mathbb{R}^n$."""
        if self.group is None:
            return ""
        names = self.velocities[self.n:]
        xi = f"xi = ({', '.join(names)})" if names else "xi"
        if self.reconstruction == "right":
            text = (f"R reconstructed from the space velocity {xi} = (dR/dt R^-1)^vee: dR/dt = hat(xi) R; "
                    "steps R_(k+1) = tau(sigma_k) R_k")
        else:
            verb = "integrated with" if self.depends_on_orientation else "reconstructed from"
            text = (f"R {verb} the body velocity {xi} = (R^-1 dR/dt)^vee: dR/dt = R hat(xi); "
                    "steps R_(k+1) = R_k tau(sigma_k)")
        return f"{text}; {self.orientation_note}" if self.orientation_note else text

    @property
    def parameters(self) -> dict[str, float]:
        """The system's parameters as a dict (for provenance)."""
        return dict(self.params)

    def _args(self, b):
        if self.group is None:
            return (b,)
        return (b.x, b.R) if self.depends_on_orientation else (b.x,)

    def _leading(self) -> tuple[str, ...]:
        """The names of the functions' leading arguments (the base point)."""
        if self.group is None:
            return ("q",)
        return ("x", "R") if self.depends_on_orientation else ("x",)

    def _dtype(self, b):
        """The floating type of the base point's coordinates (float64 without any)."""
        return jnp.result_type(self.space.coordinates(b)) if self.n else jnp.float64

    def _call(self, f, *xs):
        """`f(*xs)`, or `f(*xs, args)` for a system with named parameters (:attr:`args`)."""
        return f(*xs) if self.args is None else f(*xs, self.args)

    def _call_force(self, *xs):
        """The force at `xs`, with the named parameters last when it takes them (:attr:`force_args`)."""
        return self.force(*xs, self.args) if self.force_args else self.force(*xs)

    def with_args(self, **values) -> "System":
        """A copy with the named parameters `values` replaced (:attr:`args`), e.g. a mass being
        differentiated: `jax.grad(lambda m: loss(gnipy.simulate(system.with_args(m=m), q0, v0, ...)))`.
        Unknown names raise InputError; the provenance `params` follow (a traced value is recorded
        as NaN, :func:`gnipy.inputs.provenance_number`). The default initial condition follows the
        new values on a model's systems (the zoo's, a user's function: :attr:`rebuild`); on others,
        and for traced values, it is dropped, and a run asks for `q0` and `v0`."""
        if not isinstance(self.args, dict):
            raise InputError("args: this system has no named parameters (System(..., args={...}))")
        unknown = [k for k in values if k not in self.args]
        if unknown:
            raise InputError(f"args: unknown parameter {unknown[0]!r} (known: {', '.join(self.args)})")
        for k, v in values.items():  # the same shapes: the functions, and a batch's structure, expect them
            if jnp.shape(v) != jnp.shape(self.args[k]):
                raise InputError(f"args: parameter {k!r} has shape {jnp.shape(self.args[k])}, got a value of "
                                 f"shape {jnp.shape(v)}")
        new_args = system_args({**self.args, **values})
        params = dict(self.params)
        params.update(provenance(scalar_args(new_args), None)[0])
        # the default initial condition (and the note on R) were made for the old values: those of
        # the new ones where the model can build them, else none (a run then asks for q0 and v0)
        rebuilt = None
        if self.rebuild is not None and not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(new_args)):
            rebuilt = self.rebuild({k: float(v) for k, v in scalar_args(new_args).items()})
        return self._replaced(args=new_args, params=provenance(params, None)[0],
                              defaults=None if rebuilt is None else rebuilt.defaults,
                              orientation_note="" if rebuilt is None else rebuilt.orientation_note)

    @traced_once
    def L(self, b, v):
        """The Lagrangian $l(b, v)$ at a base point."""
        return self._call(self.lagrangian, *self._args(b), v)

    @traced_once
    def metric(self, b):
        """The kinetic-energy metric $\\mathbb{G}(b) = \\partial^2 l / \\partial v^2$ (N×N)."""
        return jax.hessian(lambda v: self.L(b, v))(jnp.zeros(self.dim))

    @traced_once
    def potential(self, b):
        """The potential $V(b) = -l(b, 0)$."""
        return -self.L(b, jnp.zeros(self.dim))

    @traced_once
    def potential_gradient(self, b):
        """$\\partial V / \\partial q$ on $\\mathbb{R}^n$; on $\\mathbb{R}^n\\times G$ the
        $(\\partial V/\\partial x, \\nabla^L_R V)$ (left-trivialized)."""
        return jax.grad(lambda w: self.potential(self.space.move(b, w)))(jnp.zeros(self.dim))

    @traced_once
    def momentum(self, b, v):
        """The Legendre transform $p = \\partial l / \\partial v = \\mathbb{G}(b) v$."""
        return jax.grad(lambda w: self.L(b, w))(v)

    def velocity(self, b, p):
        """Inverse Legendre transform $v = \\mathbb{G}(b)^{-1} p$."""
        from .linalg import solve_spd

        return solve_spd(self.metric(b), p)

    @traced_once
    def mu(self, b):
        """The velocity constraints' one-forms as an (m, N) array: the nonholonomic rows
        (:meth:`nonholonomic_mu`) followed by the differentials of the holonomic constraints
        (:meth:`holonomic_mu`), so that $\\mu(b)(v - Y(b)) = 0$ says everything the velocity must
        satisfy."""
        if self.holonomic is None:
            return self.nonholonomic_mu(b)
        return jnp.concatenate([self.nonholonomic_mu(b), self.holonomic_mu(b)], axis=0)

    def nonholonomic_mu(self, b):
        """The user's constraint one-forms (`constraints`) as an (m, N) array ((0, N) without any)."""
        if self.constraints is None:
            return jnp.zeros((0, self.dim), dtype=self._dtype(b))
        return jnp.atleast_2d(jnp.asarray(self._call(self.constraints, *self._args(b))))

    @traced_once
    def phi(self, b):
        """The holonomic constraints $\\varphi(b)$, shape (r,) ((0,) without any)."""
        if self.holonomic is None:
            return jnp.zeros((0,), dtype=self._dtype(b))
        return jnp.atleast_1d(jnp.asarray(self._call(self.holonomic, *self._args(b)))).reshape(-1)

    @traced_once
    def holonomic_mu(self, b):
        """The differentials $d\\varphi(b)$ as (r, N) rows in the velocity coordinates (on
        $\\mathbb{R}^n\\times G$ left-trivialized: the derivative along :meth:`~gnipy.spaces.GroupSpace.move`)."""
        return jax.jacfwd(lambda w: self.phi(self.space.move(b, w)))(jnp.zeros(self.dim))

    @traced_once
    def Y(self, b):
        """Affine part $Y(b)$ (zero for linear constraints). With holonomic constraints, the field
        with the same $\\mu Y$ on the nonholonomic rows and $d\\varphi\\,Y = 0$
        (:func:`gnipy.holonomic.affine_part`): only $\\mu Y$ enters the equations."""
        if self.affine is None:
            return jnp.zeros(self.dim, dtype=self._dtype(b))
        Y = jnp.asarray(self._call(self.affine, *self._args(b))).reshape(self.dim)
        if self.holonomic is None:
            return Y
        from .holonomic import affine_part

        return affine_part(self.metric(b), self.nonholonomic_mu(b), self.holonomic_mu(b), Y)

    def Pi(self, b):
        """The one-form $\\Pi = \\mathbb{G} Y$ of paper §6."""
        return self.metric(b) @ self.Y(b)

    @traced_once
    def energy(self, b, v):
        """Energy $\\tfrac12 v^T \\mathbb{G} v + V$."""
        return 0.5 * v @ self.metric(b) @ v + self.potential(b)

    def constraint_residual(self, b, v):
        """$\\mu(b)(v - Y(b))$, one entry per row of :meth:`mu`, followed by $\\varphi(b)$ for the
        holonomic constraints (:meth:`num_constraints` entries)."""
        res = self.mu(b) @ (v - self.Y(b))
        if self.holonomic is None:
            return res
        return jnp.concatenate([res, self.phi(b)])

    @property
    def is_affine(self) -> bool:
        """Whether the constraints have an affine part."""
        return self.affine is not None

    # ----------------------------------------------------------------------------------------
    # Forces and inputs (gnipy.forcing)
    # ----------------------------------------------------------------------------------------
    @property
    def is_forced(self) -> bool:
        """Whether the system carries a generalized force."""
        return self.force is not None

    def external_force(self, b, v, t=None):
        """The generalized force $F(b, v, u(t), t)$ (zero without a force); `t` defaults to the
        start of the step being taken, the input is the drive's (:class:`gnipy.forcing.Drive`)."""
        if self.force is None:
            return jnp.zeros_like(v)
        t = self.drive.t if t is None else t
        u = self.drive.u(t)
        return jnp.asarray(self._call_force(*self._args(b), v, u, t), dtype=v.dtype).reshape(v.shape)

    def external_force_continuous(self, b, v, t):
        """$F(b, v, u(t), t)$ with the input held over the step that contains `t` (the
        continuous equations, :meth:`gnipy.forcing.Drive.u_continuous`)."""
        if self.force is None:
            return jnp.zeros_like(v)
        u = self.drive.u_continuous(t)
        return jnp.asarray(self._call_force(*self._args(b), v, u, t), dtype=v.dtype).reshape(v.shape)

    def with_force(self, force: Callable[..., Any], inputs: int = 0) -> "System":
        """A copy of this system with the generalized force `force` and `inputs` inputs (see the
        constructor), e.g. a torque on a closed-over sleigh: `system.with_force(lambda q, v, u, t:
        jnp.array([0.0, 0.0, u[0]]), inputs=1)`. On a system with named parameters (:attr:`args`,
        as the zoo's models) a force that takes one more argument receives them last,
        `F(q, v, u, t, args)`; `F(q, v, u, t)` keeps working."""
        if not callable(force):
            raise InputError(f"force: expected a callable F(q, v, u, t), got {type(force).__name__}")
        if isinstance(inputs, bool) or int(inputs) != inputs or inputs < 0:
            raise InputError(f"inputs: expected a non-negative integer, got {inputs!r}")
        from .forcing import Drive

        return self._replaced(force=force, inputs=int(inputs), drive=Drive.make(inputs=int(inputs)),
                              force_args=self.args is not None and takes_args_last(force, len(self._leading()) + 4))

    def as_model(self, model: str, rebuild: Callable[..., Any] | None = None) -> "System":
        """This system recorded as the zoo model `model` (what the zoo's builds return,
        :func:`gnipy.registry.register`): the model's registered invariants and measured default
        method (:func:`gnipy.get_model`) then apply to it. A System written by hand is no model's,
        whatever its `name`."""
        return self._replaced(model=str(model), rebuild=rebuild)

    def as_user_model(self, reference: str, digest: str | None, rebuild: Callable[..., Any] | None = None
                      ) -> "System":
        """This system recorded as built by the user's function `reference` (`FILE.py:NAME` or
        `module:NAME`, :mod:`gnipy.user_systems`) from a source of SHA-256 `digest` (and
        :attr:`rebuild`, how to build it again)."""
        return self._replaced(origin=(str(reference), None if digest is None else str(digest)), rebuild=rebuild)

    def driven(self, drive) -> "System":
        """A copy of this system with the :class:`gnipy.forcing.Drive` `drive` (its inputs)."""
        if self.force is None:
            raise InputError("controls: the system has no force (System(..., force=F) or system.with_force(F))")
        return eqx.tree_at(lambda s: s.drive, self, drive)

    def at_step(self, k) -> "System":
        """The system during step k (its drive's step and time set); itself when unforced."""
        if self.force is None:
            return self
        return eqx.tree_at(lambda s: s.drive, self, self.drive.at_step(k))

    def shifted(self, dt) -> "System":
        """The system with its step's start time moved by `dt` (sub-steps); itself when unforced."""
        if self.force is None:
            return self
        return eqx.tree_at(lambda s: s.drive, self, self.drive.shifted(dt))

    def without_metadata(self) -> "System":
        """A copy without the provenance fields `params`, `origin`, `rebuild`, `defaults` and
        `orientation_note`.

        This is what compiled code receives: systems that differ only in parameter values then
        share one compilation, and can be stacked into a batch (their parameters are array
        leaves: its `args`, or `jax.tree_util.Partial` arguments of its functions).
        """
        return self._replaced(params=(), origin=None, rebuild=None, defaults=None, orientation_note="")

    def _replaced(self, **fields) -> "System":
        """A copy with `fields` set (static ones too, which `eqx.tree_at` cannot set)."""
        import dataclasses

        new = object.__new__(type(self))
        for f in dataclasses.fields(self):
            object.__setattr__(new, f.name, fields.get(f.name, getattr(self, f.name)))
        return new

    # ----------------------------------------------------------------------------------------
    # Validation (host side, outside jit)
    # ----------------------------------------------------------------------------------------
    def num_constraints(self, b) -> int:
        """The number of entries of :meth:`constraint_residual` at the base point b: the rows of
        :meth:`mu`, plus the r holonomic constraints $\\varphi$ themselves."""
        return int(jax.eval_shape(self.constraint_residual, b, jnp.zeros(self.dim)).shape[0])

    def project_configuration(self, b):
        """The configuration on the holonomic constraints $\\varphi = 0$ nearest to `b` in the
        metric (Newton's iterations, :func:`gnipy.holonomic.project_configuration`): e.g. a
        bicycle's pitch from its roll and steer, or a pendulum's coordinates rescaled to its
        length. `b` is `q` on $\\mathbb{R}^n$, a :class:`~gnipy.spaces.Point` on
        $\\mathbb{R}^n\\times G$; returned unchanged without holonomic constraints."""
        from .holonomic import project_configuration

        if self.holonomic is None:
            return b
        if self.group is None:
            b = jnp.asarray(b, dtype=jnp.float64)
        return project_configuration(self.without_metadata(), b)

    def initial_point(self, q0, R0=None):
        """The validated base point from coordinates `q0` and (on $\\mathbb{R}^n\\times G$) an
        orientation `R0` (default: the identity)."""
        return checks.initial_point(self, q0, R0)

    def check(self, q0, v0=None, *, R0=None, project_v0: bool = False, tol: float = 1e-10):
        """Validate the system at the initial point and return `(b0, v0)` (float64).

        `b0` is `q0` on $\\mathbb{R}^n$ and `Point(q0, R0)` on $\\mathbb{R}^n\\times G$.
        Checks: shapes and finiteness; that `l` is of mechanical type (quadratic in `v` with no
        linear term, at `b0` and nearby points); that the metric is symmetric positive definite;
        that the constraints have full row rank; that `v0` satisfies the constraints.

        Arguments:
            q0: initial coordinates, length n.
            v0: initial velocity, length N (optional).
            R0: initial orientation on $\\mathbb{R}^n\\times G$ (default the identity).
            project_v0: project `v0` onto the constraint space ($\\mathbb{G}$-orthogonally)
                instead of raising when it violates the constraints.
            tol: tolerance of the checks.

        Raises:
            InputError: naming the argument and the problem.
        """
        return checks.check_system(self, q0, v0, R0=R0, project_v0=project_v0, tol=tol)

    def check_mechanical(self, b0, *, tol: float = 1e-9, samples: int = 3):
        """Raise :class:`InputError` unless `l(b, v) = ½vᵀG(b)v − V(b)` at and near `b0`
        (`samples` points: `b0` and random nearby ones; compiled once per system structure)."""
        del samples  # fixed at gnipy.system_checks.SAMPLES so that the compiled check is shared
        check_mechanical_type(checks.validation_values_at(self, b0), checks.SAMPLES, tol=tol)

    def has_constant_metric(self, b0) -> bool:
        """Whether the metric does not depend on the base point (exact zero derivative at samples).

        Automatic differentiation returns an exact zero for a metric that does not depend on the
        base point, and a nonzero value almost surely at random points otherwise.
        """
        return checks.has_constant_metric(self, b0)

    def _default_point(self):
        """The base point of the default initial condition (`defaults`), or the origin (and the
        identity orientation) where the system has none: where probes such as
        :meth:`lagrangian_depends_on` and the methods' `check` look at it."""
        return checks.default_point(self)

    def lagrangian_depends_on(self, part: str = "configuration") -> bool:
        """Whether $l(b, v)$ depends on the base point: `"configuration"`, on any of its coordinates
        (x and, on $\\mathbb{R}^n \\times G$, R); `"orientation"`, on R.

        Decided as :meth:`has_constant_metric` is: automatic differentiation returns exact zeros
        for coordinates that $l$ does not use, and nonzero values almost surely at random points
        and velocities otherwise (here 3 points near the default initial condition, compiled once
        per system structure). A system whose parameters are traced (under `jax.jit` or
        `jax.grad`) has no values to test: it is said to depend on them.
        It decides which methods are symmetric on the system (:meth:`gnipy.integrators.base.Integrator.symmetric_on`).
        """
        return checks.lagrangian_depends_on(self, part)


def describe_orientations(systems) -> str:
    """The file attribute `orientation` of a run of `systems` (one System, or the members of a
    batch): :attr:`System.orientation_description`, the members' different notes joined (e.g.
    where R is physical for some parameter values and not for others); empty on $\\mathbb{R}^n$."""
    if isinstance(systems, System):
        systems = [systems]
    texts = list(dict.fromkeys(s.orientation_description for s in systems))
    if len(texts) <= 1:
        return texts[0] if texts else ""
    notes = list(dict.fromkeys(s.orientation_note for s in systems if s.orientation_note))
    base = systems[0].without_metadata().orientation_description
    return f"{base}; depending on the member: " + " | ".join(notes)
