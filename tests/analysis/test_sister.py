"""Sister systems (gnipy.analysis.sister): the sister motion of the knife edge against the model's
exact solution, the energy balance of the plastic impacts, the sister method against the sister
motion (exact where each phase has a constant acceleration, order 3 locally elsewhere), and the
checks of the arguments."""

import numpy as np
import pytest

import gnipy
from gnipy.analysis import fitted_order
from gnipy.analysis.sister import sister_method, sister_trajectory
from gnipy.errors import InputError
from gnipy.experiments.open_questions import sleigh_peg
from gnipy.models.knife_edge import exact

KNIFE = gnipy.model_systems("knife-edge")[0]
Q0, V0 = (np.asarray(x, dtype=float) for x in KNIFE.defaults[:2])
TAUS = (0.1, 0.05, 0.025)


@pytest.fixture(scope="module")
def knife_runs():
    return {tau: sister_trajectory(KNIFE, Q0, V0, tau=tau, t_final=1.0) for tau in TAUS}


def test_sister_motion_converges_at_order_one_to_the_exact_knife_edge(knife_runs):
    errors = []
    for tau, run in knife_runs.items():
        q, _ = exact(KNIFE.parameters, Q0, V0, run.t)
        errors.append(np.abs(run.q - q).max())
    assert 0.9 < fitted_order(TAUS, errors) < 1.1
    # each phase keeps its holonomic constraint, and the velocity after each impact is on the distribution
    for run in knife_runs.values():
        assert run.constraint.max() < 1e-12
        mu = np.stack([np.asarray(KNIFE.mu(q))[0] for q in run.q])
        assert np.abs(np.einsum("kn,kn->k", mu, run.v)).max() < 1e-12


def test_energy_is_conserved_between_impacts_and_lost_only_at_them(knife_runs):
    # the phases are holonomic motions with the model's Lagrangian: E changes only by the impacts' losses
    for run in knife_runs.values():
        assert np.all(run.lost >= -1e-15)
        assert abs((run.energy[0] - run.energy[-1]) - run.lost.sum()) < 1e-10 * max(1.0, abs(run.energy[0]))
    # and the loss per unit time is O(τ): halving τ halves it
    losses = [knife_runs[tau].lost.sum() for tau in TAUS]
    assert 0.9 < fitted_order(TAUS, losses) < 1.1


def test_sister_method_is_the_sister_motion_where_phases_have_constant_acceleration():
    # on the knife edge's rail the metric is constant, gravity's force constant and the constraint
    # linear: each phase has a constant acceleration, which RATTLE's velocity Verlet integrates exactly
    exact_run = sister_trajectory(KNIFE, Q0, V0, tau=0.1, t_final=1.0)
    method = sister_method(KNIFE, Q0, V0, h=0.1, t_final=1.0)
    assert np.abs(method.q - exact_run.q).max() < 1e-12
    assert np.abs(method.v - exact_run.v).max() < 1e-12
    # the registered method "sister" (gnipy.SisterMethod) is that method in simulate, which says that it
    # dissipates the energy the motion conserves
    sol = gnipy.simulate(KNIFE, "sister", Q0, V0, h=0.1, steps=10)
    assert np.abs(np.asarray(sol.q) - exact_run.q).max() < 1e-12
    assert np.abs(np.asarray(sol.energy) - exact_run.energy).max() < 1e-12
    assert "dissipates" in sol.conserved


def test_sister_method_agrees_with_the_sister_phase_to_second_order_under_a_curved_potential():
    particle = gnipy.model_systems("nonholonomic-particle")[0]
    q0, v0 = particle.defaults[:2]
    hs = (0.1, 0.05, 0.025)
    diffs = [np.abs(sister_method(particle, q0, v0, h=h, t_final=h).q[-1]
                    - sister_trajectory(particle, q0, v0, tau=h, t_final=h).q[-1]).max() for h in hs]
    assert 2.8 < fitted_order(hs, diffs) < 3.2


def test_the_sleigh_peg_is_a_sister_constraint_and_converges():
    sleigh = gnipy.model_systems("chaplygin-sleigh")[0]
    q0, v0 = sleigh.defaults[:2]
    ref = gnipy.simulate(sleigh, "reference", q0, v0, h=0.025, steps=20)
    errors = []
    for tau in (0.1, 0.05, 0.025):
        run = sister_trajectory(sleigh, q0, v0, tau=tau, t_final=0.5, constraint=sleigh_peg(sleigh))
        errors.append(np.abs(run.q - np.asarray(ref.q)[::int(round(tau / 0.025))]).max())
        assert run.constraint.max() < 1e-12
    assert 0.8 < fitted_order((0.1, 0.05, 0.025), errors) < 1.2


def test_bad_arguments_are_refused_by_name():
    with pytest.raises(InputError, match="tau"):
        sister_trajectory(KNIFE, Q0, V0, tau=0.3, t_final=1.0)  # not a whole number of phases
    with pytest.raises(InputError, match="tau"):
        sister_trajectory(KNIFE, Q0, V0, tau=-0.1, t_final=1.0)
    with pytest.raises(InputError, match="v0"):
        sister_trajectory(KNIFE, Q0, np.array([0.0, 1.0, 0.0]), tau=0.1, t_final=1.0)  # sideways
    with pytest.raises(InputError, match="constraint"):  # not tangent to the distribution at the anchor
        sister_trajectory(KNIFE, Q0, V0, tau=0.1, t_final=1.0, constraint=lambda q, a: (q - a)[:1])
    ball = gnipy.model_systems("rolling-ball")[0]
    with pytest.raises(InputError, match="system"):
        sister_trajectory(ball, *ball.defaults[:2], tau=0.1, t_final=1.0)
