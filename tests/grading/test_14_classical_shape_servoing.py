"""Grading: lesson 14, classical shape servoing (reference: dlo_course.jacobian).

The three pieces of the controller are pure functions of arrays: each is compared with the
library on fixed inputs built here (linear systems x = A u whose Jacobian A is known, and a
few awkward cases), then its secondary requirement is checked: the ValueError of probes that
do not span the three axes, and of a negative damping. The inputs cross to the student's code
as plain data; the probes below run in the grading sandbox, the checks here.
"""

import numpy as np
import pytest

from dlo_course import jacobian

pytestmark = pytest.mark.notebook("14_classical_shape_servoing")


def linear_system(seed, n_nodes):
    """A (3m, 3): the Jacobian of a rod that moves exactly linearly with its tip."""
    return np.random.default_rng(seed).normal(size=(3 * n_nodes, 3))


# ------------------------------------------------------------------ jacobian_from_probes


def probe_cases():
    """(tip_moves, node_moves, as_lists): one move per axis, any 3 independent moves, more
    probes than needed (exact and noisy: least squares), one node, moves given as lists."""
    rng = np.random.default_rng(140)
    cases = []
    A = linear_system(1, 4)
    tip = 0.02 * np.eye(3)
    cases.append((tip, tip @ A.T, False))
    A = linear_system(2, 2)
    tip = rng.normal(scale=0.02, size=(3, 3))
    cases.append((tip, tip @ A.T, False))
    A = linear_system(3, 6)
    tip = rng.normal(scale=0.01, size=(5, 3))
    cases.append((tip, tip @ A.T, False))
    tip = rng.normal(scale=0.01, size=(7, 3))
    cases.append((tip, tip @ A.T + rng.normal(scale=1e-3, size=(7, 18)), False))  # noisy
    A = linear_system(4, 1)
    tip = np.diag([0.02, -0.01, 0.03]) + rng.normal(scale=0.002, size=(3, 3))
    cases.append((tip, tip @ A.T, True))
    return cases


def probe_jacobian_from_probes(fn, cases):
    out = []
    for tip, nodes, as_lists in cases:
        tip_in, nodes_in = (tip.tolist(), nodes.tolist()) if as_lists else (tip.copy(),
                                                                            nodes.copy())
        out.append(np.asarray(fn(tip_in, nodes_in)))
    return out


def check_jacobians(got, cases):
    for k, ((tip, nodes, _), mine) in enumerate(zip(cases, got, strict=True)):
        want = jacobian.jacobian_from_probes(tip, nodes)
        where = f"case {k}: {len(tip)} probes, {nodes.shape[1] // 3} nodes"
        assert mine.shape == want.shape, \
            f"{where}: J of shape {mine.shape}, expected {want.shape} (3m rows, 3 columns)"
        assert mine.dtype == np.float64, f"{where}: J of dtype {mine.dtype}, expected float64"
        np.testing.assert_allclose(mine, want, rtol=1e-8, atol=1e-10, err_msg=(
            f"{where}: J must be the least-squares solution of tip_moves @ J.T = node_moves"))


@pytest.mark.exercise("jacobian_from_probes", points=1.5,
                      reference="dlo_course.jacobian.jacobian_from_probes")
def test_jacobian_from_probes(student):
    cases = probe_cases()
    check_jacobians(student.run(probe_jacobian_from_probes, cases), cases)


def probe_jacobian_from_probes_span(fn):
    """The exception raised for probes that miss the z axis (3 of them, and 2), or None."""
    A = linear_system(5, 2)
    flat = np.array([[0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [0.01, 0.01, 0.0]])
    raised = []
    for tip in (flat, flat[:2]):
        try:
            fn(tip, tip @ A.T)
            raised.append(None)
        except Exception as err:  # noqa: BLE001
            raised.append(type(err).__name__)
    return raised


@pytest.mark.exercise("jacobian_from_probes", points=0.5,
                      reference="dlo_course.jacobian.jacobian_from_probes")
def test_jacobian_from_probes_refuses_probes_that_miss_an_axis(student):
    """The secondary requirement (the ValueError), worth points only with a right J."""
    cases = probe_cases()
    try:
        check_jacobians(student.run(probe_jacobian_from_probes, cases), cases)
    except AssertionError:
        pytest.fail("the Jacobian itself is wrong: no points for the check of the probes",
                    pytrace=False)
    raised = student.run(probe_jacobian_from_probes_span)
    assert raised == ["ValueError", "ValueError"], (
        f"probes that do not span the 3 axes must raise ValueError (raised: {raised}): "
        "J would be undetermined along the missing axis")


# ------------------------------------------------------------------------ broyden_update


def broyden_cases():
    """(J, du, dP, kwargs): a wrong J and the true move, the defaults, partial gains, a move
    at and below min_move, a move of zero, a right J (nothing to correct)."""
    rng = np.random.default_rng(141)
    cases = []
    for seed, n_nodes, kwargs in [(10, 4, {}), (11, 2, {"gain": 0.3}), (12, 6, {"gain": 1.0}),
                                  (13, 1, {"gain": 0.5, "min_move": 0.002})]:
        A = linear_system(seed, n_nodes)
        J = A + rng.normal(scale=0.5, size=A.shape)
        du = rng.normal(scale=0.01, size=3)
        cases.append((J, du, A @ du, kwargs))
    A = linear_system(14, 4)
    J = A + rng.normal(scale=0.5, size=A.shape)
    cases.append((J, np.array([0.005, 0.0, 0.0]), A[:, 0] * 0.005,
                  {"gain": 1.0, "min_move": 0.005}))  # exactly at min_move: J stays
    cases.append((J, np.array([0.001, -0.001, 0.0]), A @ [0.001, -0.001, 0.0],
                  {"gain": 0.3, "min_move": 0.002}))  # below min_move: J stays
    cases.append((J, np.zeros(3), rng.normal(scale=0.001, size=12), {}))  # no move at all
    cases.append((A, np.array([0.01, -0.02, 0.005]), A @ [0.01, -0.02, 0.005], {"gain": 0.3}))
    return cases


def probe_broyden_update(fn, cases):
    """The student's new J for each case, and whether the input J stayed as it was and the
    result is a new array."""
    out = []
    for J, du, dp, kwargs in cases:
        J_in = J.copy()
        new = fn(J_in, du.copy(), dp.copy(), **kwargs)
        out.append({"J": np.array(new), "untouched": bool(np.array_equal(J_in, J)),
                    "new_array": not (isinstance(new, np.ndarray)
                                      and np.shares_memory(new, J_in))})
    return out


@pytest.mark.exercise("broyden_update", points=2, reference="dlo_course.jacobian.broyden_update")
def test_broyden_update(student):
    cases = broyden_cases()
    got = student.run(probe_broyden_update, cases)
    for k, ((J, du, dp, kwargs), mine) in enumerate(zip(cases, got, strict=True)):
        want = jacobian.broyden_update(J, du, dp, **kwargs)
        where = f"case {k}: |du| = {np.linalg.norm(du):.4g} m, arguments {kwargs or 'defaults'}"
        assert mine["J"].shape == want.shape, \
            f"{where}: J_new of shape {mine['J'].shape}, expected {want.shape}"
        assert mine["J"].dtype == np.float64, \
            f"{where}: J_new of dtype {mine['J'].dtype}, expected float64"
        np.testing.assert_allclose(mine["J"], want, rtol=1e-9, atol=1e-12, err_msg=(
            f"{where}: J_new = J + gain (dP - J du) du^T / (du^T du), or J itself when "
            f"|du| <= min_move"))
        assert mine["untouched"], f"{where}: broyden_update changed the J it was given"
        assert mine["new_array"], f"{where}: J_new must be a new array, not the input J"


# ------------------------------------------------------------- damped_least_squares_step


def step_cases():
    """(J, error, damping): no damping (least squares; a reachable error), some damping,
    much damping, one node (a square J), and a nearly singular J, damped."""
    rng = np.random.default_rng(142)
    cases = []
    A = linear_system(20, 4)
    cases.append((A, rng.normal(scale=0.05, size=12), 0.0))
    cases.append((A, A @ np.array([0.01, 0.02, -0.03]), 0.0))
    cases.append((A, rng.normal(scale=0.05, size=12), 0.3))
    B = linear_system(21, 6)
    cases.append((B, rng.normal(scale=0.05, size=18), 2.5))
    cases.append((linear_system(22, 1), rng.normal(scale=0.05, size=3), 0.7))
    C = linear_system(23, 2)
    C[:, 2] = C[:, 0] + 1e-6 * rng.normal(size=6)  # two columns almost equal
    cases.append((C, rng.normal(scale=0.05, size=6), 0.3))
    return cases


def probe_damped_least_squares_step(fn, cases):
    return [np.asarray(fn(J.copy(), error.copy(), damping)) for J, error, damping in cases]


def check_steps(got, cases):
    for k, ((J, error, damping), mine) in enumerate(zip(cases, got, strict=True)):
        want = jacobian.damped_least_squares_step(J, error, damping)
        where = f"case {k}: J {J.shape}, damping {damping}"
        assert mine.shape == want.shape, f"{where}: du of shape {mine.shape}, expected (3,)"
        assert mine.dtype == np.float64, f"{where}: du of dtype {mine.dtype}, expected float64"
        np.testing.assert_allclose(mine, want, rtol=1e-7, atol=1e-12, err_msg=(
            f"{where}: du = (J^T J + damping^2 I)^-1 J^T e"))


@pytest.mark.exercise("damped_least_squares_step", points=1.5,
                      reference="dlo_course.jacobian.damped_least_squares_step")
def test_damped_least_squares_step(student):
    cases = step_cases()
    check_steps(student.run(probe_damped_least_squares_step, cases), cases)


def probe_damped_least_squares_step_negative(fn):
    """The exception raised for a negative damping, or None."""
    try:
        fn(linear_system(24, 2), np.full(6, 0.01), -0.3)
    except Exception as err:  # noqa: BLE001
        return type(err).__name__
    return None


@pytest.mark.exercise("damped_least_squares_step", points=0.5,
                      reference="dlo_course.jacobian.damped_least_squares_step")
def test_damped_least_squares_step_refuses_a_negative_damping(student):
    """The secondary requirement (the ValueError), worth points only with a right step."""
    cases = step_cases()
    try:
        check_steps(student.run(probe_damped_least_squares_step, cases), cases)
    except AssertionError:
        pytest.fail("the step itself is wrong: no points for the check of the damping",
                    pytrace=False)
    raised = student.run(probe_damped_least_squares_step_negative)
    assert raised == "ValueError", (
        f"a negative damping must raise ValueError (raised: {raised}): only its square "
        "enters the formula, and a negative value is a mistake of the caller")


# ------------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_controller_vs_agent", points=1)
def test_prediction_controller_vs_agent(written_answer):
    written_answer.check()
