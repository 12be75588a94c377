"""No solve reports failure at round-off (gnipy.integrators.base.newton, its round-off floor).

Every method on one zoo model of each structure and every zoo model with each kind of solve (see
:data:`CASES`), at h = 1e-1 down to 1e-5, from the model's documented initial
condition: at h ≤ 1e-2 no step may fail; at h = 1e-1 a failure is allowed only as a genuine one,
with a residual far above round-off. Before the floor test, `mp` stopped at step 3 of
`rotating-table-ball` at h = 1e-4 with "did not converge (residual 4.441e-16)": its multiplier is
only determined to ~ε|v|/h, which no relative correction test below 1e-12 can meet.
"""

import pytest

import gnipy

HS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5)
STEPS = 12
#: Every method runs on one model of each structure the solvers meet: R^n with a linear constraint
#: (the sleigh), SE(2) (its group twin), SO(3) with a potential (the top), affine constraints (the
#: rotating-table ball, where `mp` once stopped at round-off) and the contact oscillator written for
#: `mp`. Every other model runs with the methods whose solves differ from one another: the GNI's
#: impulse solve, the SGNI's, the discrete Lagrange-d'Alembert constraint, `mp`'s multiplier and the
#: discrete gradient's. Each pair compiles its own program (~1-2 s); all 270 pairs took a fifth of
#: the suite, and these 140 meet every solver on every kind of model.
FLOOR_MODELS = ("chaplygin-sleigh", "chaplygin-sleigh-se2", "chaplygin-top", "rotating-table-ball",
                "contact-oscillator-mp")
FLOOR_METHODS = ("gni-midpoint", "sgni-trapezoid", "dla", "mp", "discrete-gradient")
CASES = [(model, method) for model in gnipy.model_names() for method in gnipy.method_names()
         if method != "reference" and (model in FLOOR_MODELS or method in FLOOR_METHODS)]


@pytest.mark.slow
@pytest.mark.parametrize(("model", "method"), CASES)
def test_no_failure_at_round_off(model, method):
    system = gnipy.make_system(model)
    for h in HS:
        try:
            # the solver's floor, not the verdicts, is under test here: the loop without the every-node
            # check compiles in about half the time (270 programs)
            sol = gnipy.simulate(system, method, h=h, steps=STEPS, save_every=STEPS, check_every_node=False)
        except gnipy.MethodError:
            return  # the method does not apply to this model (e.g. mp on a group)
        except gnipy.SolverFailure as e:
            assert h > 1e-2 and e.residual > 1e-8, f"h = {h:g}: {e}"
            continue
        assert sol.result == 0 and len(sol.t) == 2
