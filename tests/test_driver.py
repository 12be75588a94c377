"""The driver's policies: SaveAt, continuing from a state, a shortened last step, progress, results."""

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.analysis import fitted_order

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False


@pytest.fixture(scope="module")
def ball():
    return gnipy.make_system("rolling-ball")


def test_saveat_policies_save_the_nodes_asked_for(ball):
    every = gnipy.simulate(ball, "gni-trapezoid", h=0.01, steps=100)
    for saveat, nodes in [(gnipy.SaveAt(every=30), [0, 30, 60, 90, 100]), (gnipy.SaveAt(t1=True), [100]),
                          (gnipy.SaveAt(t0=True, t1=True), [0, 100]), (gnipy.SaveAt(ts=[0.25, 0.5], t1=True), [25, 50, 100]),
                          (gnipy.SaveAt(steps=True), list(range(101)))]:
        sol = gnipy.simulate(ball, "gni-trapezoid", h=0.01, steps=100, saveat=saveat)
        np.testing.assert_allclose(np.asarray(sol.t), 0.01 * np.asarray(nodes), rtol=1e-15)
        # the same nodes as the every-node run, bit for bit (one loop, whatever it saves)
        np.testing.assert_array_equal(np.asarray(sol.q), np.asarray(every.q)[nodes])
        np.testing.assert_array_equal(np.asarray(sol.R), np.asarray(every.R)[nodes])


def test_a_run_continued_from_its_final_state_equals_the_whole_run(ball):
    whole = gnipy.simulate(ball, "gni-midpoint", h=0.02, steps=60, save_every=20)
    first = gnipy.simulate(ball, "gni-midpoint", h=0.02, steps=20, save_every=20)
    rest = gnipy.simulate(ball, "gni-midpoint", h=0.02, steps=40, save_every=20, state0=first.final_state,
                          t0=float(first.t[-1]))
    np.testing.assert_array_equal(np.asarray(rest.q), np.asarray(whole.q)[1:])
    np.testing.assert_array_equal(np.asarray(rest.p), np.asarray(whole.p)[1:])
    with pytest.raises(gnipy.InputError, match="state0: give either state0 or the initial condition"):
        gnipy.simulate(ball, "gni-midpoint", ball.defaults[0], ball.defaults[1], h=0.02, steps=2,
                       state0=first.final_state)
    with pytest.raises(gnipy.InputError, match="state0: not a state of"):
        gnipy.simulate(ball, "gni-midpoint", h=0.02, steps=2, state0=(jnp.zeros(2),))


def test_a_shortened_last_step_keeps_the_order_two():
    """t_final - t0 not a multiple of h: the GNI's last step is shortened (its hidden impulse
    rescaled); the error against the exact solution of the vertical disk (uniform rolling) is
    fitted to order 2."""
    spec = gnipy.get_model("vertical-disk")
    system = spec.system()
    q0 = np.array([0.0, 0.0, 0.3, 0.0])
    v0 = np.array([np.cos(0.3) * 0.8, np.sin(0.3) * 0.8, 0.7, 0.8])  # x' = r cos(φ) θ', y' = r sin(φ) θ'
    T = 1.03
    exact = spec.exact if getattr(spec, "exact", None) else None
    hs = [0.1, 0.05, 0.025, 0.0125]
    errors = []
    for h in hs:
        sol = gnipy.simulate(system, "gni-midpoint", q0, v0, h=h, t_final=T, saveat=gnipy.SaveAt(t1=True))
        assert abs(float(sol.t[-1]) - T) < 1e-15
        phi = 0.3 + 0.7 * T
        x = 0.8 / 0.7 * (np.sin(phi) - np.sin(0.3))
        y = -0.8 / 0.7 * (np.cos(phi) - np.cos(0.3))
        errors.append(np.max(np.abs(np.asarray(sol.q[-1]) - [x, y, phi, 0.8 * T])))
    del exact
    assert 1.8 < fitted_order(hs, errors) < 2.2, errors
    with pytest.raises(gnipy.InputError, match=r"t_final: .* shake cannot shorten its last step; choose h = "):
        gnipy.simulate(system, "shake", q0, v0, h=0.1, t_final=T)


def test_progress_reports_every_step_range_and_the_end(ball):
    seen = []
    gnipy.simulate(ball, "gni-trapezoid", h=0.01, steps=1000, saveat=gnipy.SaveAt(t1=True),
                   progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (1000, 1000) and len(seen) > 10
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))


def test_results_are_readable(ball):
    sol = gnipy.simulate(ball, "gni-trapezoid", h=0.01, steps=10)
    assert sol.success and sol.result == gnipy.RESULTS.successful and sol.message == "every step converged"
    html = sol._repr_html_()
    assert "gnipy.Solution" in html and "rolling-ball" in html and "success" in html
    particle = gnipy.make_system("nonholonomic-particle")
    bad = gnipy.simulate(particle, "gni-midpoint", (0.0, 0.0, 0.0), (1e200, 0.0, 0.0), h=1e200, steps=5,
                         throw=False, project_v0=True)
    assert not bad.success and bad.result == gnipy.RESULTS.solve_failed
    assert bad.message.startswith("step 0") and "did not converge" in bad.message
    assert "FAILED" in bad._repr_html_()


def test_member_summary_reports_its_own_iterations():
    systems = gnipy.model_systems("vertical-disk", r=[0.5, 1.0])
    sol = gnipy.simulate(systems, "gni-midpoint", h=0.05, steps=20)
    per = np.asarray(sol.member_iterations)
    assert per.shape == (2, 2) and per[:, 0].sum() == int(sol.iterations[0])
    for i in range(2):
        assert tuple(np.asarray(sol.member(i).iterations)) == tuple(per[i])


def test_node_buckets_cover_each_count_with_at_most_a_quarter_more():
    from gnipy.preparation import node_bucket

    counts = (0, 1, 16, 17, 20, 21, 1000, 1024, 1025)
    assert [node_bucket(n) for n in counts] == [16, 16, 16, 20, 20, 24, 1024, 1024, 1280]
    for n in range(17, 5000):
        assert n <= node_bucket(n) <= 1.25 * n, n


def test_node_counts_in_one_bucket_share_a_program_and_equal_an_exact_one(monkeypatch):
    """Runs saving 11, 14 and 16 nodes share one program (16 nodes, the extra ones of no steps cut);
    their nodes, and those of a run whose shortened last step's node is saved (a program of its
    own), are those of programs compiled for exactly their counts, bit for bit."""
    from gnipy import preparation
    from gnipy.assembly import _NODE_DIAGNOSTICS

    # the process's compiled programs and prepared runs set aside: earlier tests may have compiled these
    monkeypatch.setattr(preparation, "_PROGRAMS", {})
    monkeypatch.setattr(preparation, "_CACHE", {})
    sleigh = gnipy.make_system("chaplygin-sleigh")

    def runs():
        return [gnipy.simulate(sleigh, "gni-midpoint", h=0.01, steps=100, save_every=10),  # 11 nodes
                gnipy.simulate(sleigh, "gni-midpoint", h=0.01, steps=130, save_every=10),  # 14
                gnipy.simulate(sleigh, "gni-midpoint", h=0.01, steps=150, save_every=10),  # 16
                gnipy.simulate(sleigh, "gni-midpoint", h=0.01, t_final=1.305, save_every=10)]  # 15, the last at 1.305

    def run_programs():
        return sum(key[0] == "run" for key in preparation._PROGRAMS)

    before = run_programs()
    bucketed = runs()
    assert run_programs() - before == 2
    assert [len(s.t) for s in bucketed] == [11, 14, 16, 15] and float(bucketed[3].t[-1]) == 1.305
    monkeypatch.setattr(preparation, "node_bucket", lambda n: n)
    for a, b in zip(bucketed, runs(), strict=True):
        for name in ("t", "q", "v", "p", "energy", "constraint_residual", *_NODE_DIAGNOSTICS):
            np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)), err_msg=name)
    assert run_programs() - before == 5  # 11, 14 and 15 exactly; 16 is its own bucket's program
