"""The capstone's loop skeleton (visla_edu.course.capstone) and its checks (notebook 12)."""

from dataclasses import replace

import numpy as np
import pytest

from fdiff import fd_jacobian  # tests/fdiff.py
from visla_edu import data, lie, run, simulate
from visla_edu.course import capstone, checks
from visla_edu.camera import StereoCamera
from visla_edu.filters import FilterConfig, StepRecord
from visla_edu.stepper import Stepper

from answers import capstone_landmarks as add_landmarks  # tests/answers.py
from answers import capstone_predict as predict
from answers import capstone_slam as slam_update

STEPS = capstone.Steps(predict, add_landmarks, slam_update)


@pytest.fixture(scope="module")
def tiny():
    ds = data.load("sim-tiny")
    return ds, run.resolve_config(ds, FilterConfig(slam_error="right", msckf_window=0))


def test_the_library_parts_jacobians_match_finite_differences():
    """pose_jacobian (right perturbation mu exp(delta^)), landmark_jacobian, and the new-landmark
    sensitivity G of the reference add_landmarks, at random poses, against finite differences."""
    from visla_edu.course.checks import _capstone

    parts = capstone.library_parts()
    camera = StereoCamera(*simulate.default_rig())
    Ks, cam_T_imu = camera.Ks, camera.cam_T_imu
    rng = np.random.default_rng(8)
    for _ in range(3):
        mu = lie.se3_exp(np.r_[rng.normal(0, 10, 3), rng.normal(0, 0.5, 3)])
        p_cam = np.r_[rng.uniform(-5, 5), rng.uniform(-2, 2), rng.uniform(4, 50)]
        m = (mu @ camera.imu_T_cam @ np.r_[p_cam, 1.0])[:3]
        J_pose = fd_jacobian(lambda d: parts.project(Ks, cam_T_imu, mu @ lie.se3_exp(d), m[None])[0],
                             np.zeros(6), 1e-5)
        J_lm = fd_jacobian(lambda x: parts.project(Ks, cam_T_imu, mu, x[None])[0], m, 1e-4)
        np.testing.assert_allclose(parts.pose_jacobian(Ks, cam_T_imu, mu, m), J_pose, rtol=1e-6,
                                   atol=1e-6 * np.abs(J_pose).max())
        np.testing.assert_allclose(parts.landmark_jacobian(Ks, cam_T_imu, mu, m), J_lm, rtol=1e-6,
                                   atol=1e-6 * np.abs(J_lm).max())
        z = camera.predict(mu, m[None])
        p_new, G = _capstone._sensitivities(parts, mu, z, camera.K, camera.b, camera.imu_T_cam)
        G_fd = fd_jacobian(lambda d: parts.init_landmark(z[0], camera.K, camera.b, camera.imu_T_cam,
                                                         mu @ lie.se3_exp(d)), np.zeros(6), 1e-5)
        np.testing.assert_allclose(p_new[0], m, atol=1e-8)
        np.testing.assert_allclose(G[0], G_fd, rtol=1e-7, atol=1e-7 * np.abs(G_fd).max())


def test_the_pose_updates_written_out_equal_the_library_update():
    """capstone's parts.pose_update and the pose-update check's reference build H from the formula
    -Ks dpi/dq o_T_i (mu^-1 m)^odot; their updates equal ekf.pose_update, whose Jacobians are
    checked against finite differences (tests/test_camera.py)."""
    from visla_edu import ekf
    from visla_edu.course.checks import _filters

    parts = capstone.library_parts()
    camera = StereoCamera(*simulate.default_rig())
    rng = np.random.default_rng(9)
    for k in (1, 6):
        mu = lie.se3_exp(np.r_[rng.normal(0, 10, 3), rng.normal(0, 0.5, 3)])
        p_cam = np.c_[rng.uniform(-5, 5, k), rng.uniform(-2, 2, k), rng.uniform(4, 40, k)]
        p_world = (np.c_[p_cam, np.ones(k)] @ (mu @ camera.imu_T_cam).T)[:, :3]
        z = camera.predict(mu @ lie.se3_exp(rng.normal(0, 0.05, 6)), p_world) + rng.normal(0, 1.0, (k, 4))
        A = rng.normal(0, 0.05, (6, 6))
        Sigma = A @ A.T + 1e-4 * np.eye(6)
        T_ref, S_ref, _ = ekf.pose_update(mu, Sigma, p_world, z, camera, 4.0)
        for update in (parts.pose_update, _filters._pose_update_with):
            T_new, S_new = update(mu, Sigma, z, p_world, camera.Ks, camera.cam_T_imu, 4.0)
            np.testing.assert_allclose(T_new, T_ref, atol=1e-10)
            np.testing.assert_allclose(0.5 * (S_new + S_new.T), S_ref, atol=1e-12)


def test_the_skeleton_with_correct_steps_is_the_library_right_perturbation_filter(tiny):
    ds, config = tiny
    poses, covs, landmarks = capstone.run_capstone(ds, config, capstone.library_parts(), STEPS)
    library = run.run_filter(ds, "slam", config, progress=False)
    assert np.abs(poses - library.world_T_imu).max() < 1e-8
    assert np.abs(covs - library.pose_cov).max() < 1e-10
    placed = np.isfinite(library.landmarks[:, 0])
    np.testing.assert_array_equal(np.isfinite(landmarks[:, 0]), placed)
    assert np.abs(landmarks[placed] - library.landmarks[placed]).max() < 1e-7


def test_vio_skeleton_steps_and_records(tiny):
    ds, config = tiny
    flt = capstone.CapstoneFilter(ds, config, capstone.library_parts(), STEPS, joint=False)
    records = [flt.step() for _ in range(20)]
    assert all(isinstance(r, StepRecord) for r in records) and records[-1].t == 19
    assert flt.Sigma.shape == (6, 6) and np.isfinite(records[-1].nis)
    assert len(records[-1].active_ids) and np.all(np.isfinite(records[-1].active_covs))
    poses, covs, _ = capstone.run_capstone(ds, config, capstone.library_parts(), STEPS, joint=False)
    np.testing.assert_allclose(poses[:20], [r.world_T_imu for r in records], atol=1e-9)
    assert np.linalg.norm(poses[:, :3, 3] - ds.ground_truth.world_T_imu[:, :3, 3], axis=1).max() < 2.0


def test_a_wrong_shape_names_the_function_and_frame(tiny):
    ds, config = tiny
    bad = replace(STEPS, predict=lambda parts, T, Sigma, u, tau, W: (T, Sigma[:6, :6]))
    flt = capstone.CapstoneFilter(ds, config, capstone.library_parts(), bad)
    with pytest.raises(ValueError, match=r"predict returned Sigma of shape \(6, 6\) at frame \d+, expected"):
        for _ in range(10):
            flt.step()
    with pytest.raises(TypeError, match="capstone.Parts"):
        capstone.CapstoneFilter(ds, config, {}, STEPS)


def test_the_stepper_steps_the_capstone_filter(tiny):
    ds, config = tiny
    s = Stepper(ds, config=config, filter_factory=lambda d, c: capstone.CapstoneFilter(d, c, capstone.library_parts(),
                                                                                       STEPS))
    rec = s.goto(15)
    assert isinstance(s.filter, capstone.CapstoneFilter) and rec.t == 15 and len(rec.active_ids)
    library = Stepper(ds, config=config)
    np.testing.assert_allclose(rec.world_T_imu, library.goto(15).world_T_imu, atol=1e-9)


@pytest.mark.parametrize("check, answer", [(checks.check_capstone_predict, predict),
                                           (checks.check_capstone_landmarks, add_landmarks),
                                           (checks.check_capstone_slam, slam_update)])
def test_correct_answers_pass(check, answer, capsys):
    check(answer)
    check(answer, hidden=True)
    out = capsys.readouterr().out
    assert out.count("\u2713") == 1


def _cross_missing(parts, T, Sigma, *args):
    p_new, out = add_landmarks(parts, T, Sigma, *args)
    D = len(Sigma)
    out[D:, :D] = 0
    out[:D, D:] = 0
    return p_new, out


def _predict_without_parts(parts, T, Sigma, u, tau, W):
    """Right numbers, but the mean through the library's se3_exp instead of parts.se3_exp."""
    library_parts = replace(parts, se3_exp=lie.se3_exp)
    return predict(library_parts, T, Sigma, u, tau, W)


@pytest.mark.parametrize("check, wrong, hint", [
    (checks.check_capstone_predict,
     lambda parts, T, S, u, tau, W: (parts.se3_exp(tau * u) @ T, predict(parts, T, S, u, tau, W)[1]),
     "the mean moves on the right"),
    (checks.check_capstone_predict, lambda parts, T, S, u, tau, W: predict(parts, T, S, u, tau, 0 * W),
     "the motion noise W is missing"),
    (checks.check_capstone_predict, _predict_without_parts, "use parts.se3_exp"),
    (checks.check_capstone_landmarks, _cross_missing, "cross-covariance G Sigma_px is missing"),
    (checks.check_capstone_slam, lambda parts, T, S, p, *args: slam_update(parts, T, S, p, *args)[:2] + (p,),
     "every landmark in the state moves"),
])
def test_mistakes_are_named(check, wrong, hint):
    with pytest.raises(AssertionError, match=hint):
        check(wrong)


def test_capstone_steps_falls_back_on_unfinished_functions(capsys):
    def stub(*args):
        raise NotImplementedError

    steps = checks.capstone_steps(predict, stub, lambda *args: (1, 2, 3))
    out = capsys.readouterr().out
    assert steps.predict is predict
    assert steps.add_landmarks is not stub and steps.slam_update.__name__ == "_reference_slam_update"
    assert "using your predict" in out and "using the reference add_landmarks" in out
