"""Grading that cannot be gamed: hidden library functions, fresh checks, an intact library, hidden cases.

* While a check runs the student's function, the library's version of the exercise raises
  "write your own ..." under every name (module attribute, ``from ... import`` alias, a library
  function that calls it) and comes back afterwards, even when the student's code raises.
* A graded cell reloads ``visla_edu.course.checks``: nothing an answer cell assigned to the checks
  (or their submodules) survives.
* A library function replaced by notebook code, or a module attribute reassigned while the
  check runs, fails the check (and the attribute is put back).
* ``hidden=True`` runs other cases silently; a table of the visible answers does not pass them.
"""

import importlib

import numpy as np
import pytest
import scipy.linalg

import answers as A  # tests/answers.py
import visla_edu.course.checks
from visla_edu import camera as cam
from visla_edu import diagnostics, ekf, lie, metrics, motion
from visla_edu.course import checks, kalman
from visla_edu.course.checks import _hiding
from visla_edu.simulate import default_rig

FIRST_HAT = "write your own hat; the library's lie.hat is not available inside this check"


def _first_line(err):
    return str(err).split("\n", 1)[0]


def _failure(check, fn, **kwargs):
    with pytest.raises(AssertionError) as info, np.errstate(all="ignore"):
        check(fn, **kwargs)
    return info.value


def _notebook_function(source, name, **names):
    """A function defined as in a notebook cell (its module is ``__main__``)."""
    namespace = {"__name__": "__main__", "np": np, **names}
    exec(compile(source, "/tmp/ipykernel_0/cell.py", "exec"), namespace)  # noqa: S102 - test fixture
    return namespace[name]


# --------------------------------------------------------------------------- hiding


def test_hidden_error_message_is_short_and_names_the_function():
    assert len(FIRST_HAT) <= 79
    message = _hiding.hidden_message("average_nees_bounds", metrics.average_nees_bounds)
    assert len(_first_line(message)) <= 79 and _first_line(message).startswith("write your own average_nees_bounds")
    assert _hiding.function_label(cam.StereoCamera.predict) == "camera.StereoCamera.predict"
    assert _hiding.function_label(checks.reference_numerical_jacobian) == "numdiff.central_jacobian"


def test_hidden_error_message_of_a_long_exercise_name_keeps_the_name():
    long_name = "estimate_the_landmark_covariance_of_the_map"  # 43 characters: no phrasing fits
    message = _hiding.hidden_message(long_name, cam.StereoCamera.predict)
    assert _first_line(message) == f"write your own {long_name}"
    assert len(_first_line(message)) <= 79 and "camera.StereoCamera.predict" in message.split("\n")[1]


def _alias_answers():
    from visla_edu.lie import hat as imported_hat  # the student's own binding, made before the check

    import visla_edu as package

    return {
        "lie.hat": lambda w: lie.hat(w),
        "visla_edu.lie.hat": lambda w: package.lie.hat(w),
        "from-import alias": lambda w: imported_hat(w),
        "through twist_hat": lambda w: lie.twist_hat(np.r_[0.0, 0.0, 0.0, w])[:3, :3],
        "through curly_hat": lambda w: lie.curly_hat(np.r_[0.0, 0.0, 0.0, w])[3:, 3:],
    }


@pytest.mark.parametrize("how", list(_alias_answers()))
def test_library_hat_is_hidden_under_every_name(how):
    err = _failure(checks.check_hat, _alias_answers()[how])
    assert _first_line(err) == FIRST_HAT
    np.testing.assert_array_equal(lie.hat([1.0, 2.0, 3.0]), A.hat([1.0, 2.0, 3.0]))  # restored


@pytest.mark.parametrize("check, answer, hidden_name", [
    (checks.check_so3_exp, lambda w: lie.so3_exp(w), "lie.so3_exp"),
    (checks.check_so3_exp, lambda w: lie.se3_exp(np.r_[0.0, 0.0, 0.0, w])[:3, :3], "lie.se3_exp"),
    (checks.check_se3_exp, lambda u: motion.predict_pose(np.eye(4), u, 1.0), "lie.se3_exp"),
    (checks.check_dead_reckon, lambda ts, u, lag=0: motion.dead_reckon(ts, u, lag=lag), "motion.dead_reckon"),
    (checks.check_so3_log, lambda R: lie.so3_log(R), "lie.so3_log"),
    (checks.check_white_noise, lambda u: diagnostics.imu_noise(u)["white"], "diagnostics.imu_noise"),
    (checks.check_left_pose_prediction, lambda mu, S, u, tau, W: (mu @ lie.se3_exp(tau * u),
                                                                   motion.predict_invariant_covariance(
        S.copy(), mu @ lie.se3_exp(tau * u), np.zeros((0, 3)), W)), "motion.predict_invariant_covariance"),
    (checks.check_landmark_observation_noise, lambda J, S, r: ekf.innovation_covariances(None, J, None, None, S, r),
     "ekf.innovation_covariances"),
    (checks.check_slam_null_space, lambda T, p: checks.reference_slam_null_space(T, p), "reference_slam_null_space"),
    (checks.check_invariant_pose_jacobian, lambda Ks, o, T, m: ekf.invariant_pose_jacobian(
        cam.StereoCamera(*default_rig()).jacobian_landmark(T, m[None]))[0], "ekf.invariant_pose_jacobian"),
    (checks.check_gate, lambda r, S, p: ekf.mahalanobis_squared(r, S) <= metrics.chi2_quantile(p, 4),
     "ekf.mahalanobis_squared"),
    (checks.check_align_rigid, lambda e, g: metrics.align_se3(e, g), "metrics.align_se3"),
    (checks.check_pose_marginal_covariance, lambda *a: checks.reference_pose_marginal_covariance(*a),
     "reference_pose_marginal_covariance"),
    (checks.check_project, lambda Ks, o, T, p: cam.StereoCamera(
        [[Ks[0, 0], 0, Ks[0, 2]], [0, Ks[1, 1], Ks[1, 2]], [0, 0, 1]], -Ks[2, 3] / Ks[0, 0],
        lie.se3_inv(o)).predict(T, p), "camera.StereoCamera.predict"),
    (checks.check_triangulate, lambda z, K, b: cam.triangulate_disparity(z, K, b), "camera.triangulate_disparity"),
    (checks.check_numerical_jacobian, lambda f, x: checks.reference_numerical_jacobian(f, x),
     "numdiff.central_jacobian"),
    (checks.check_pose_transition, lambda u, tau: lie.adjoint(lie.se3_exp(-tau * u)), "lie.adjoint"),
    (checks.check_pose_update, lambda mu, S, z, p, Ks, o, nv: ekf.pose_update(
        mu, S, p, z, cam.StereoCamera(*default_rig()), nv)[:2], "ekf.pose_update"),
    (checks.check_average_nees_bounds, lambda d, n, p=0.95: np.array(metrics.chi2_bounds(d * n, p)) / n,
     "metrics.chi2_bounds"),
    (checks.check_nees, lambda e, P: float(metrics.nees(e[None], P[None])[0]), "metrics.nees"),
    (checks.check_kalman_update_1d, lambda m, v, z, r: kalman.update_1d(m, v, z, r), "kalman.update_1d"),
    (checks.check_kalman_update_1d, lambda m, v, z, r: tuple(
        np.ravel(a)[0] for a in kalman.update([m], [[v]], [z - m], [[1.0]], [[r]])), "kalman.update"),
    (checks.check_kalman_predict, lambda x, P, F, Q: kalman.predict(x, P, F, Q), "kalman.predict"),
    (checks.check_so3_exp, lambda w: scipy.linalg.expm(lie.hat(w)), "scipy.linalg.expm"),
    (checks.check_se3_exp, lambda u: scipy.linalg.expm(lie.twist_hat(u)), "scipy.linalg.expm"),
])
def test_library_versions_are_hidden(check, answer, hidden_name):
    err = _failure(check, answer)
    first, second = (str(err).split("\n") + [""])[:2]
    assert first.startswith("write your own"), str(err)
    # the first line names the hidden function when it fits in 79 characters (long exercise names), else the second
    assert hidden_name in (first if len(f"write your own {check.__name__[6:]}: {hidden_name} is hidden here") <= 79
                           else second), str(err)
    assert len(first) <= 79


def _library_copies():
    """Answers that take a whole exercise from the capstone's parts or the camera's batched projection."""
    from visla_edu.course import capstone

    parts = capstone.library_parts()  # bound in an answer cell, before the check

    def poses(T, n):
        return np.repeat(np.asarray(T)[None], n, axis=0)

    return [
        (checks.check_project, lambda *a: parts.project(*a), "capstone._project"),
        (checks.check_project, lambda Ks, o, T, p: cam.stereo_projection(Ks, o, poses(T, len(p)), p, False)[0],
         "camera.stereo_projection"),
        (checks.check_pose_jacobian, lambda *a: parts.pose_jacobian(*a), "capstone._pose_jacobian"),
        (checks.check_pose_jacobian, lambda Ks, o, T, m: cam.stereo_projection(Ks, o, poses(T, 1), m[None])[3][0],
         "camera.stereo_projection"),
        (checks.check_landmark_jacobian, lambda *a: parts.landmark_jacobian(*a), "capstone._landmark_jacobian"),
        (checks.check_landmark_jacobian, lambda Ks, o, T, m: cam.stereo_projection(Ks, o, poses(T, 1), m[None])[2][0],
         "camera.stereo_projection"),
        (checks.check_init_landmark, lambda *a: parts.init_landmark(*a), "capstone._init_landmark"),
        (checks.check_pose_update, lambda *a: parts.pose_update(*a), "capstone._pose_update"),
        (checks.check_slam_jacobian, lambda *a: parts.slam_jacobian(*a), "capstone._slam_jacobian"),
        (checks.check_marginalize, lambda *a: parts.marginalize(*a), "capstone._marginalize"),
    ]


@pytest.mark.parametrize("index", range(len(_library_copies())))
def test_library_copies_of_an_exercise_are_hidden_too(index):
    """capstone.library_parts() holds the library's version of seven exercises; stereo_projection computes three."""
    check, answer, hidden_name = _library_copies()[index]
    err = _failure(check, answer)
    assert _first_line(err).startswith("write your own") and hidden_name in str(err), str(err)


def test_kalman_predict_cannot_take_its_covariance_from_the_pose_prediction():
    """motion.predict_pose_covariance(P, F, Q) is F P F^T + Q for any size: the exercise's formula."""
    err = _failure(checks.check_kalman_predict, lambda x, P, F, Q: (
        np.asarray(F) @ np.asarray(x), motion.predict_pose_covariance(np.asarray(P), np.asarray(F), np.asarray(Q))))
    assert _first_line(err).startswith("write your own kalman_predict") and "motion.predict_pose_covariance" in str(err)


def test_reference_jacobian_bound_before_a_reload_is_still_hidden():
    reference = checks.reference_numerical_jacobian  # bound in an answer cell
    fresh = importlib.reload(visla_edu.course.checks)
    err = _failure(fresh.check_numerical_jacobian, lambda f, x: reference(f, x))
    assert "numdiff.central_jacobian" in _first_line(err)


def test_library_is_restored_even_when_the_student_code_raises():
    original = lie.hat.__code__, lie.so3_exp.__code__, lie.so3_exp.__defaults__

    def calls_then_crashes(w):
        try:
            lie.hat(w)
        except checks.LibraryFunctionHidden:
            pass
        raise ZeroDivisionError("boom")

    with pytest.raises(AssertionError, match="ZeroDivisionError"):
        checks.check_hat(calls_then_crashes)

    def stub(w):
        raise NotImplementedError

    with pytest.raises(NotImplementedError):
        checks.check_so3_exp(stub)
    assert (lie.hat.__code__, lie.so3_exp.__code__, lie.so3_exp.__defaults__) == original
    np.testing.assert_allclose(lie.so3_exp(np.array([0.0, 0.0, np.pi / 2])) @ [1.0, 0, 0], [0, 1.0, 0], atol=1e-15)


def test_functions_with_defaults_come_back_with_them():
    saved = motion.dead_reckon.__defaults__
    _failure(checks.check_dead_reckon, lambda ts, u: motion.dead_reckon(ts, u))
    assert motion.dead_reckon.__defaults__ == saved
    assert motion.dead_reckon(np.array([0.0, 1.0]), np.zeros((2, 6))).shape == (2, 4, 4)


def test_allowed_library_functions_stay_available(capsys):
    """so3_exp may use lie.hat; se3_exp may use lie.so3_exp (the exercise texts say so)."""
    checks.check_so3_exp(lambda w: np.eye(3) + A._coefficients(w @ w)[0] * lie.hat(w)
                         + A._coefficients(w @ w)[1] * lie.hat(w) @ lie.hat(w))
    checks.check_se3_exp(lambda u: np.block([[lie.so3_exp(u[3:]), A.se3_exp(u)[:3, 3:]], [np.zeros((1, 3)), 1.0]]))
    assert capsys.readouterr().out.count("\u2713") == 2


# --------------------------------------------------------------------------- fresh checks for graded cells


def _fresh_checks():
    """What a graded cell does: reload the checks and use the result through a local name."""
    return importlib.reload(visla_edu.course.checks)


@pytest.fixture
def reloaded_checks():
    """Reload the checks after the test, whatever it assigned."""
    yield
    importlib.reload(visla_edu.course.checks)


def test_overwritten_check_does_not_survive_the_graded_cell(reloaded_checks):
    checks.check_hat = lambda f, hidden=False: None  # an answer cell tampering with the check
    import visla_edu.course.checks as c

    c.check_so3_exp = lambda f, hidden=False: print("\u2713 so3_exp")
    visla_edu.course.checks._kinematics.check_se3_exp = lambda f, hidden=False: None
    visla_edu.course.checks._core.compare = lambda *args, **kwargs: None
    fresh = _fresh_checks()
    wrong = lambda w: np.zeros((3, 3))  # noqa: E731
    assert "hat" in _first_line(_failure(fresh.check_hat, wrong))
    assert "so3_exp" in _first_line(_failure(fresh.check_so3_exp, wrong))
    assert "se3_exp" in _first_line(_failure(fresh.check_se3_exp, lambda u: np.eye(4)))


def test_replaced_library_function_fails_the_check(monkeypatch):
    fake = _notebook_function("def hat(w):\n    return np.zeros((3, 3))\n", "hat")
    monkeypatch.setattr(lie, "hat", fake)  # the reference would now agree with a wrong answer
    err = _failure(checks.check_hat, fake)
    assert _first_line(err) == "visla_edu's lie.hat was replaced by code from this notebook"
    assert all(len(line) <= 79 for line in str(err).split("\n")), str(err)  # nbgrader validate shows them whole


def test_swapped_library_code_fails_the_check(monkeypatch):
    fake = _notebook_function("def so3_exp(w):\n    return np.eye(3)\n", "so3_exp")
    monkeypatch.setattr(lie.so3_exp, "__code__", fake.__code__)
    err = _failure(checks.check_so3_exp, lambda w: np.eye(3))
    assert "lie.so3_exp was replaced" in _first_line(err)


def test_replaced_method_fails_the_check(monkeypatch):
    fake = _notebook_function("def predict(self, T, p):\n    return np.zeros((len(p), 4))\n", "predict")
    monkeypatch.setattr(cam.StereoCamera, "predict", fake)
    err = _failure(checks.check_project, lambda *a: np.zeros((12, 4)))
    assert "camera.StereoCamera.predict was replaced" in _first_line(err)


def test_changing_the_checks_while_they_run_fails_and_is_undone(reloaded_checks):
    from visla_edu.course.checks import _core

    compare = _core.compare

    def sneaky_hat(w):
        _core.compare = lambda *args, **kwargs: None
        return np.zeros((3, 3))

    err = _failure(checks.check_hat, sneaky_hat)
    assert _first_line(err) == "your hat changed visla_edu while the check ran"
    assert all(len(line) <= 79 for line in str(err).split("\n")), str(err)
    assert _core.compare is compare


def test_numpy_replaced_by_notebook_code_fails_the_check(monkeypatch):
    """``np.allclose = lambda *a, **k: True`` in an answer cell would pass every wrong answer."""
    monkeypatch.setattr(np, "allclose", _notebook_function("def allclose(*a, **k):\n    return True\n", "allclose"))
    err = _failure(checks.check_hat, lambda w: np.zeros((3, 3)))
    assert _first_line(err) == "numpy.allclose was replaced by code from this notebook"
    monkeypatch.undo()
    monkeypatch.setattr(np.linalg, "solve", lambda a, b: b)
    err = _failure(checks.check_nees, A.nees)
    assert _first_line(err) == "numpy.linalg.solve was replaced by code from this notebook"


def test_replaced_builtin_fails_the_check(monkeypatch):
    import builtins

    class AlwaysTrue(int):
        def __new__(cls, x=False):
            return True

    monkeypatch.setattr(builtins, "bool", AlwaysTrue)  # bool(np.allclose(...)) would always be True
    err = _failure(checks.check_hat, lambda w: np.zeros((3, 3)))
    assert _first_line(err) == "Python's built-in bool was replaced by code from this notebook"


def test_changing_numpy_or_builtins_while_the_check_runs_fails_and_is_undone():
    import builtins

    allclose, real_float = np.allclose, builtins.float

    def sneaky_hat(w):
        np.allclose = lambda *args, **kwargs: True
        return np.zeros((3, 3))

    def sneaky_so3_exp(w):
        builtins.float = lambda x: 0.0  # every error measured by the check would be 0
        return np.eye(3)

    assert _first_line(_failure(checks.check_hat, sneaky_hat)) == "your hat changed numpy while the check ran"
    assert np.allclose is allclose
    err = _failure(checks.check_so3_exp, sneaky_so3_exp)
    assert _first_line(err) == "your so3_exp changed builtins while the check ran"
    assert builtins.float is real_float
    checks.check_hat(A.hat)


def test_reloading_the_library_inside_the_answer_fails():
    def reloading_hat(w):
        importlib.reload(lie)  # a fresh, unhidden lie.hat
        return lie.hat(w)

    err = _failure(checks.check_hat, reloading_hat)
    assert _first_line(err) == "your hat changed visla_edu while the check ran"
    assert "visla_edu.lie.hat" in str(err)
    checks.check_hat(A.hat)  # the library is whole again


def test_lazy_result_cannot_call_the_library_after_the_check():
    class Lazy:
        def __init__(self, w):
            self.w = w

        def __array__(self, dtype=None, copy=None):
            return lie.hat(self.w)

    err = _failure(checks.check_hat, Lazy)
    assert _first_line(err) == FIRST_HAT


# --------------------------------------------------------------------------- hidden cases


ALL_CHECKS = [getattr(checks, name) for name in checks.__all__ if name.startswith("check_")]
ANSWERS = {check: getattr(A, check.__name__.removeprefix("check_")) for check in ALL_CHECKS}


@pytest.mark.parametrize("check", ALL_CHECKS, ids=lambda c: c.__name__)
def test_hidden_cases_pass_correct_answers_silently(check, capsys):
    check(ANSWERS[check], hidden=True)
    assert capsys.readouterr().out == ""


def test_a_table_of_the_visible_answers_fails_the_hidden_cases(capsys):
    table = {}

    def recording(w):
        table[np.asarray(w, dtype=float).tobytes()] = A.hat(w)
        return A.hat(w)

    checks.check_hat(recording)
    memorised = lambda w: table.get(np.asarray(w, dtype=float).tobytes(), np.eye(3))  # noqa: E731
    checks.check_hat(memorised)  # passes the visible cases...
    assert "hat" in _first_line(_failure(checks.check_hat, memorised, hidden=True))  # ...not the hidden ones


@pytest.mark.parametrize("check", [checks.check_motion_noise, checks.check_average_nees_bounds,
                                   checks.check_dense_covariance_bytes], ids=lambda c: c.__name__)
def test_checks_with_fixed_cases_draw_more_hidden_cases_from_the_teachers_seed(check, monkeypatch, capsys):
    """A table of every case the source shows (visible and default hidden) fails under a teacher's seed."""
    from visla_edu.course.checks import _core

    answer, table = ANSWERS[check], {}

    def recording(*args):
        table[args] = answer(*args)
        return table[args]

    monkeypatch.delenv(_core.HIDDEN_SEED_VARIABLE, raising=False)
    check(recording)
    check(recording, hidden=True)
    memorised = lambda *args: table.get(args, answer(*args) * 2)  # noqa: E731
    check(memorised, hidden=True)  # the table holds every case of the default seed...
    monkeypatch.setenv(_core.HIDDEN_SEED_VARIABLE, "2718")
    with pytest.raises(AssertionError):  # ...not the teacher's
        check(memorised, hidden=True)
    check(answer, hidden=True)


def _rig_answers():
    """Answers that take the calibration from the notebooks' rig (``rig = ds.camera``), not their arguments."""
    rig = cam.StereoCamera(*default_rig())
    return {
        "check_project": lambda Ks, o, T, p: A.project(rig.Ks, rig.cam_T_imu, T, p),
        "check_pose_jacobian": lambda Ks, o, mu, m: A.pose_jacobian(rig.Ks, rig.cam_T_imu, mu, m),
        "check_landmark_jacobian": lambda Ks, o, T, m: A.landmark_jacobian(rig.Ks, rig.cam_T_imu, T, m),
        "check_init_landmark": lambda z, K, b, i_T_c, T: A.init_landmark(z, rig.K, rig.b, rig.imu_T_cam, T),
        "check_landmark_update": lambda m, S, z, T, Ks, o, r: A.landmark_update(
            m, S, z, T, rig.Ks, rig.cam_T_imu, r),
        "check_pose_update": lambda mu, S, z, p, Ks, o, r: A.pose_update(mu, S, z, p, rig.Ks, rig.cam_T_imu, r),
        "check_capstone_landmarks": lambda parts, T, S, z, K, b, i_T_c, C: A.capstone_landmarks(
            parts, T, S, z, rig.K, rig.b, rig.imu_T_cam, C),
        "check_capstone_slam": lambda parts, T, S, p, slots, z, Ks, o, r: A.capstone_slam(
            parts, T, S, p, slots, z, rig.Ks, rig.cam_T_imu, r),
    }


@pytest.mark.parametrize("name", list(_rig_answers()))
def test_the_hidden_cases_use_another_rig(name, capsys):
    """The visible cases use the notebooks' simulated rig; an answer that ignores its calibration fails hidden."""
    check, answer = getattr(checks, name), _rig_answers()[name]
    check(answer)  # the notebook's rig is the visible cases' rig...
    err = _failure(check, answer, hidden=True)  # ...not the hidden cases'
    if "capstone" not in name:
        assert "the notebook's rig was used, not the calibration arguments" in _first_line(err)


def test_hidden_seed_comes_from_the_environment(monkeypatch, capsys):
    from visla_edu.course.checks import _core

    monkeypatch.delenv(_core.HIDDEN_SEED_VARIABLE, raising=False)
    default = _core.rng(hidden=True).normal(size=3)
    monkeypatch.setenv(_core.HIDDEN_SEED_VARIABLE, "12345")
    assert not np.allclose(_core.rng(hidden=True).normal(size=3), default)
    checks.check_so3_exp(A.so3_exp, hidden=True)
    for text in ("twelve", "-5"):
        monkeypatch.setenv(_core.HIDDEN_SEED_VARIABLE, text)
        with pytest.raises(ValueError, match=f"VISLA_EDU_HIDDEN_SEED must be a non-negative integer, got '{text}'"):
            checks.check_so3_exp(A.so3_exp, hidden=True)
