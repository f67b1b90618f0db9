"""Speed, memory and accuracy of the batch and sliding-window smoothers.

Usage::

    VISLA_EDU_DATA=/path/to/course/data python benchmarks/bench_smoother.py [--cases 03 0020 ...]

Each case runs in its own process, so its peak resident memory (ru_maxrss) and its whole
wall time (interpreter start, imports, loading, EKF, smoother) are its own. Cases:

``03``         batch smoother started from the EKF on dataset 03 (1010 frames, 5105 landmarks):
               whole-process wall time, the smoother's wall and CPU time, peak memory;
``03-window``  the sliding window on 03: median and 95th-percentile time per frame;
``0020``       KITTI odometry 06 with its ground truth (``kitti_odometry_06_poses.txt``):
               ATE (no alignment; aligned in brackets) of dead reckoning, the EKF, the batch
               smoother from dead reckoning and from the EKF, and the window, for two noise
               settings: ``measured`` (the velocity noise and lag measured from the drive, what
               ``--mode smooth`` uses) and ``course`` (0.5 m/s and 0.05 rad/s, lag measured);
``0020-noisy`` its noisy twin (N(0, 0.5) m/s and N(0, 0.05) rad/s added to every velocity
               sample, seed 0), same figures;
``10``         the dataset-10 stand-in (3026 frames, simulated tracks with ground truth):
               time, memory and ATE of the EKF, batch and window;
``10-outliers`` issue 9's hard full-size drive: the stand-in with 5% gross outlier tracks and
               dataset 3's IMU lag (``data.course_standin10(outlier_share=0.05, imu_lag=1)``),
               seeds 0-2, run as ``--mode smooth`` runs it (``run.run_smoother``, everything
               measured from the data): ATE of dead reckoning, the EKF and the batch, the
               batch-to-dead-reckoning ratio, the lag the package measured, rejected observations (and
               how many observations the outlier tracks have);
``objective``  what the batch objective itself supports on ``0020`` and its noisy twin, with the
               model ``--mode smooth`` uses (noise and lag measured from the drive): ATE (no
               alignment; aligned; horizontal and vertical RMSE) after 5, 10, 20 and 40
               Levenberg-Marquardt iterations of the final round, started from the EKF and from
               the ground truth. If more iterations give a worse ATE from both starts, the
               objective's minimum, not the solver, sets the accuracy (the evidence behind the
               default ``max_iterations`` and issue 9's open target on ``0020``);
``sim``        simulated drives (preset "small", 5% outlier tracks, seeds 0-4): ATE of dead
               reckoning, EKF, batch, window "fix" and window "marginalize" (the evidence for
               the window's default) and the window's time per frame;
``solver-03``  the solver of the reduced pose system (the smoother's Schur complement at the EKF's
``solver-10``  estimate, undamped) on 03 and on the dataset-10 stand-in, median of 5 repeats with one
               BLAS thread: the hand-written envelope Cholesky (``smoother._envelope``: factor, solve,
               diagonal blocks of the inverse by the Takahashi recursion) against scipy's banded
               Cholesky (``scipy.linalg.cholesky_banded`` / ``cho_solve_banded`` on the band the
               longest track sets; the marginals by the same Takahashi recursion on the band, or by
               one banded triangular solve per block column) and scipy's sparse LU (``splu``, minimum
               degree on A^T + A; marginals by block-column solves). The scipy paths include the
               assembly of the sparse matrix (the envelope assembles inside its factorisation).
               Block-column marginals are timed on 40 block columns and extrapolated. ``step`` is what
               each Levenberg-Marquardt iteration pays (assembly, factor, solve), ``total`` a step plus
               the fastest marginals, ``run_projection`` the solver's share of the whole smoother run
               (``smoother_steps`` steps, then one factor and the marginals), each also as a ratio to
               the envelope's (``total`` also without the assembly); the band widths, and each
               result's largest relative difference to the envelope's (the systems' condition numbers
               reach 1e12, so about 1e-7 is rounding). Issue 23's rule: scipy replaces the envelope
               unless the envelope is at least twice as fast on both drives.

``--tracemalloc`` also reports the peak of Python-tracked allocations during the smoother
call (slower). Course-data cases are skipped, with a note, when the files are missing.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

CASES = ("03", "03-window", "0020", "0020-noisy", "objective", "10", "10-outliers", "sim", "solver-03",
         "solver-10")
#: Final-round iteration budgets of the ``objective`` case.
BUDGETS = (5, 10, 20, 40)
#: Velocity noise settings compared on 0020: measured from the drive ("auto", what --mode smooth uses) and
#: the course's fixed 0.5 m/s, 0.05 rad/s.
NOISE_0020 = {"measured": {}, "course": {"sigma_linear_velocity": 0.5, "sigma_angular_velocity": 0.05}}


def _peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _ate(est, truth):
    from visla_edu import metrics

    n = len(truth)
    return [round(metrics.ate(est[:n], truth, align=False), 3), round(metrics.ate(est[:n], truth, align=True), 3)]


def _timed(fn, *args, **kwargs):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def _smooth(dataset, init, landmarks, imu_T_cam, config, trace=False):
    """Run the batch smoother; returns the result and its figures (optionally tracemalloc's peak)."""
    import tracemalloc

    from visla_edu import smoother

    if trace:
        tracemalloc.start()
    result, wall, cpu = _timed(smoother.smooth, dataset, init, landmarks, imu_T_cam, config)
    figures = {"smooth_wall_s": round(wall, 2), "smooth_cpu_s": round(cpu, 2),
               "iterations": int(len(result.history["cost"])), "rejected_obs": result.rejected["outliers"],
               "dropped_landmarks": sum(v for k, v in result.rejected.items() if k.startswith("landmarks_"))}
    if trace:
        figures["tracemalloc_peak_mb"] = round(tracemalloc.get_traced_memory()[1] / 2**20, 1)
        tracemalloc.stop()
    return result, figures


def case_03(trace):
    from visla_edu import data, run, smoother

    dataset, load_s, _ = _timed(data.load, "03")
    ekf, ekf_s, _ = _timed(run.run_filter, dataset, "slam", progress=False)
    result, figures = _smooth(dataset, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam, smoother.SmootherConfig(), trace)
    return {"load_s": round(load_s, 2), "ekf_s": round(ekf_s, 2), **figures,
            "covariance_s": round(result.timing["covariance"], 2), "peak_rss_mb": round(_peak_mb())}


def _window_figures(result, truth=None):
    import numpy as np

    out = {"median_frame_ms": round(1e3 * float(np.median(result.frame_seconds[1:])), 2),
           "p95_frame_ms": round(1e3 * float(np.percentile(result.frame_seconds[1:], 95)), 2),
           "window_total_s": round(result.timing["total"], 2)}
    if truth is not None:
        out["window_ate"] = _ate(result.world_T_imu, truth)
        out["window_online_ate"] = _ate(result.online_world_T_imu, truth)
    return out


def case_03_window(_trace):
    from visla_edu import data, run, smoother

    dataset = data.load("03")
    imu_T_cam = run.make_filter(dataset, "deadreckon").camera.imu_T_cam  # the corrected extrinsic
    result = smoother.smooth_window(dataset, imu_T_cam=imu_T_cam)
    return {**_window_figures(result), "peak_rss_mb": round(_peak_mb())}


def _noisy_twin(dataset, seed=0):
    import numpy as np

    rng = np.random.default_rng(seed)
    dataset.linear_velocity = dataset.linear_velocity + rng.normal(0, 0.5, dataset.linear_velocity.shape)
    dataset.angular_velocity = dataset.angular_velocity + rng.normal(0, 0.05, dataset.angular_velocity.shape)
    return dataset


def case_0020(trace, noisy=False):
    from visla_edu import data, motion, run, smoother
    from visla_edu.filters import FilterConfig

    dataset = data.load("0020")
    truth = dataset.ground_truth.world_T_imu
    if noisy:
        dataset = _noisy_twin(dataset)
    out = {}
    for name, noise in NOISE_0020.items():
        resolved = run.resolve_config(dataset, FilterConfig(**noise))
        dead = motion.dead_reckon(dataset.time_stamps, dataset.twists, lag=resolved.imu_lag)
        out.setdefault("dead_reckoning_ate", _ate(dead, truth))
        ekf = run.run_filter(dataset, "slam", resolved, progress=False)
        config = smoother.SmootherConfig.from_filter_config(resolved)
        from_dr, figures = _smooth(dataset, dead, None, ekf.imu_T_cam, config, trace)
        from_ekf, _ = _smooth(dataset, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam, config)
        window = smoother.smooth_window(dataset, imu_T_cam=ekf.imu_T_cam, config=config)
        out[name] = {"ekf_ate": _ate(ekf.world_T_imu, truth), "smooth_from_dr_ate": _ate(from_dr.world_T_imu, truth),
                     "smooth_from_ekf_ate": _ate(from_ekf.world_T_imu, truth), **figures,
                     **_window_figures(window, truth)}
    out["peak_rss_mb"] = round(_peak_mb())
    return out


def _split_ate(est, truth):
    """ATE raw and aligned, and the raw RMSE of the horizontal (x, y) and vertical (z) position error, m."""
    import numpy as np

    n = len(truth)
    d = est[:n, :3, 3] - truth[:, :3, 3]
    return _ate(est, truth) + [round(float(np.sqrt(np.mean(np.sum(d[:, :2]**2, axis=1)))), 3),
                               round(float(np.sqrt(np.mean(d[:, 2]**2))), 3)]


def case_objective(_trace):
    import numpy as np

    from visla_edu import data, run, smoother
    from visla_edu.filters import FilterConfig

    out = {"columns": "ATE raw, ATE aligned, horizontal RMSE, vertical RMSE (m); smoother rows add the final cost "
                      "(comparable within a start only: each run rejects its own outliers)"}
    for label, noisy in (("0020", False), ("0020-noisy", True)):
        dataset = data.load("0020")
        truth = dataset.ground_truth.world_T_imu
        if noisy:
            dataset = _noisy_twin(dataset)
        config = run.resolve_config(dataset, FilterConfig())
        ekf = run.run_filter(dataset, "slam", config, progress=False)
        padded = np.concatenate([truth, np.repeat(truth[-1:], dataset.num_frames - len(truth), axis=0)])
        rows = {"ekf": " ".join(map(str, _split_ate(ekf.world_T_imu, truth)))}
        for start, poses, landmarks in (("from_ekf", ekf.world_T_imu, ekf.landmarks), ("from_truth", padded, None)):
            for budget in BUDGETS:
                settings = smoother.SmootherConfig.from_filter_config(config, max_iterations=budget,
                                                                      pose_covariance=False, landmark_covariance=False)
                result = smoother.smooth(dataset, poses, landmarks, ekf.imu_T_cam, settings)
                figures = _split_ate(result.world_T_imu, truth) + [round(float(result.history["cost"][-1]), 1)]
                rows[f"{start}_{budget}"] = " ".join(map(str, figures))
        out[label] = rows
    return out


def case_10(trace):
    from visla_edu import data, motion, run, smoother

    dataset = data.load("10")
    truth = dataset.ground_truth.world_T_imu
    ekf, ekf_s, _ = _timed(run.run_filter, dataset, "slam", progress=False)
    result, figures = _smooth(dataset, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam, smoother.SmootherConfig(), trace)
    peak = round(_peak_mb())
    window = smoother.smooth_window(dataset, imu_T_cam=ekf.imu_T_cam)
    dead = motion.dead_reckon(dataset.time_stamps, dataset.twists)
    return {"frames": dataset.num_frames, "landmarks": dataset.num_landmarks, "ekf_s": round(ekf_s, 2), **figures,
            "peak_rss_mb_batch": peak, "dead_reckoning_ate": _ate(dead, truth), "ekf_ate": _ate(ekf.world_T_imu, truth),
            "smooth_ate": _ate(result.world_T_imu, truth), **_window_figures(window, truth)}


def case_10_outliers(_trace, seeds=(0, 1, 2)):
    from visla_edu import codes, data, metrics, run

    rows = []
    for seed in seeds:
        dataset = data.course_standin10(seed=seed, outlier_share=0.05, imu_lag=1)
        truth = dataset.ground_truth.world_T_imu
        result, wall, _ = _timed(run.run_smoother, dataset, "smooth", progress=False)
        dead = metrics.ate(result.dead_reckoning, truth, align=False)
        batch = _ate(result.world_T_imu, truth)
        rows.append({"seed": seed, "measured_lag": result.config["imu_lag"], "dead_reckoning": round(dead, 1),
                     "ekf": _ate(result.start_world_T_imu, truth), "batch": batch,
                     "batch_over_dead_reckoning": round(batch[0] / dead, 4),
                     "rejected_obs": int(result.status_counts[:, codes.OBS_GATED].sum()),
                     "outlier_track_obs": int(dataset.ground_truth.outlier[dataset.obs_ids].sum()),
                     "ekf_and_batch_s": round(wall, 1)})
    return {"frames": dataset.num_frames, "rows": rows}


def case_sim(_trace, seeds=(0, 1, 2, 3, 4)):
    import numpy as np

    from visla_edu import motion, run, simulate, smoother

    rows = []
    for seed in seeds:
        dataset = simulate.simulate_drive("small", seed, outlier_share=0.05)
        truth = dataset.ground_truth.world_T_imu
        ekf = run.run_filter(dataset, "slam", progress=False)
        batch, figures = _smooth(dataset, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam, smoother.SmootherConfig())
        row = {"seed": seed, "dead_reckoning": _ate(motion.dead_reckon(dataset.time_stamps, dataset.twists), truth)[0],
               "ekf": _ate(ekf.world_T_imu, truth)[0], "batch": _ate(batch.world_T_imu, truth)[0],
               "batch_cpu_s": figures["smooth_cpu_s"]}
        for mode in smoother.WINDOW_MODES:
            window = smoother.smooth_window(dataset, config=smoother.SmootherConfig(window_mode=mode))
            row[f"window_{mode}"] = _ate(window.world_T_imu, truth)[0]
            row[f"window_{mode}_ms"] = round(1e3 * float(np.median(window.frame_seconds[1:])), 2)
        rows.append(row)
    return {"rows": rows}


# --- the reduced pose system's solver: the hand-written envelope Cholesky against scipy ---------------

#: Block columns of the inverse solved one by one (the rest extrapolated) by the "block columns" marginals.
SAMPLED_COLUMNS = 40


def _reduced_system(name):
    """The batch smoother's reduced pose system at the EKF's estimate of drive ``name``, undamped.

    The system :func:`visla_edu.smoother.smooth` factorises first (the same tracks, hence the
    same envelope, as every later step and the marginals), with the smoother's step count on
    the drive to project the solver's share of a whole run.
    """
    from visla_edu import data, run, smoother
    from visla_edu.smoother import _batch, _normal, _problem

    dataset = data.load(name)
    ekf = run.run_filter(dataset, "slam", progress=False)
    config = smoother.SmootherConfig()
    problem, m, _, _ = _batch._setup(dataset, ekf.world_T_imu, ekf.landmarks,
                                     _problem.rig_camera(dataset, ekf.imu_T_cam), config)
    _batch.drop_landmarks(problem, ekf.world_T_imu, m, config.min_observations)
    lin = _normal.linearize(problem, ekf.world_T_imu, m)
    system, rhs, _ = _normal._reduced_system(problem, lin, 0.0, _normal._landmark_factors(problem, lin, 0.0))
    result = smoother.smooth(dataset, ekf.world_T_imu, ekf.landmarks, ekf.imu_T_cam, config)
    return system, rhs, len(result.history["cost"])


def _sparse_system(system):
    """The system as a scipy.sparse CSC matrix: ``tridiag - V V^T`` with ``V`` a BSR matrix of 6x3 blocks."""
    import numpy as np
    from scipy import sparse

    n, b = system.num_blocks, system.diag.shape[1]
    i = np.arange(n)
    rows = b * np.r_[i, i[1:], i[:-1]][:, None, None] + np.arange(b)[:, None]
    cols = b * np.r_[i, i[:-1], i[1:]][:, None, None] + np.arange(b)
    blocks = np.concatenate([system.diag, system.sub, np.swapaxes(system.sub, 1, 2)])
    T = sparse.csr_matrix((blocks.ravel(), (np.broadcast_to(rows, blocks.shape).ravel(),
                                            np.broadcast_to(cols, blocks.shape).ravel())), shape=(n * b,) * 2)
    count = system.hi - system.lo + 1
    owner = np.repeat(np.arange(len(count)), count)
    within = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    row = system.lo[owner] + within
    order = np.lexsort((owner, row))
    V = sparse.bsr_matrix((system.rows[system.start[owner] + within][order], owner[order],
                           np.searchsorted(row[order], np.arange(n + 1))), shape=(n * b, 3 * len(count)))
    return (T - V @ V.T.tobsr(blocksize=(3, b))).tocsc()


def _band(S):
    """Lower band storage ``ab[i - j, j] = S[i, j]`` (scipy.linalg.cholesky_banded's, lower=True)."""
    import numpy as np
    from scipy import sparse

    L = sparse.tril(S).tocoo()
    ab = np.zeros((int((L.row - L.col).max()) + 1, S.shape[0]))
    ab[L.row - L.col, L.col] = L.data
    return ab


def _band_blocks(cb, n, b):
    """The banded factor as an EnvelopeFactor (constant reach: the band), for the Takahashi recursion."""
    import numpy as np
    from scipy import linalg

    from visla_edu.smoother import _envelope

    u = cb.shape[0] - 1
    lo = np.arange(0, n, _envelope.GROUP)
    hi = np.minimum(lo + _envelope.GROUP, n) - 1
    reach = np.minimum(hi + -(-u // b), n - 1)
    diag_inv, below = [], []
    for s, e, c in zip(lo, hi, reach):
        cols, rows = np.arange(b * s, b * (e + 1)), np.arange(b * s, b * (c + 1))
        d = rows[:, None] - cols
        L = np.where((d >= 0) & (d <= u), cb[np.clip(d, 0, u), cols], 0.0)
        k = len(cols)
        diag_inv.append(linalg.solve_triangular(L[:k], np.eye(k), lower=True))
        below.append(L[k:])
    return _envelope.EnvelopeFactor(lo, hi, reach, diag_inv, below, b)


def _block_columns(solve, n):
    """Diagonal blocks of ``A^{-1}`` at SAMPLED_COLUMNS block columns, and the seconds for all ``n`` extrapolated.

    ``solve(i)`` returns ``A^{-1}[i, i]`` from a solve for block column ``i`` (or its lower part).
    """
    import numpy as np

    sample = np.linspace(0, n - 1, SAMPLED_COLUMNS).astype(int)
    start = time.perf_counter()
    blocks = np.array([solve(i) for i in sample])
    return (sample, blocks), (time.perf_counter() - start) * n / len(sample)


def _banded_column(cb, b, i):
    """``A^{-1}[i, i] = |L^{-1} E_i|^2``: one forward banded triangular solve from row ``b i`` (LAPACK tbtrs)."""
    import numpy as np
    from scipy.linalg import lapack

    rhs = np.zeros((cb.shape[1] - b * i, b))
    rhs[:b] = np.eye(b)
    x, _ = lapack.dtbtrs(cb[:, b * i:], rhs, uplo="L")
    return x.T @ x


def _lu_column(lu, n, b, i):
    """``A^{-1}[i, i]`` from SuperLU's solve for the block column ``E_i``."""
    import numpy as np

    rhs = np.zeros((n * b, b))
    rhs[b * i:b * (i + 1)] = np.eye(b)
    return lu.solve(rhs)[b * i:b * (i + 1)]


def _seconds(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` and its wall time."""
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def _pass_envelope(system, rhs):
    """One factor, solve and diagonal of the inverse by the hand-written envelope solver: seconds, outputs."""
    from visla_edu.smoother import _envelope

    t = {}
    factor, t["factor"] = _seconds(_envelope.cholesky, system)
    x, t["solve"] = _seconds(_envelope.solve, factor, rhs)
    cov, t["marginals"] = _seconds(_envelope.inverse_diagonal, factor)
    return t, {"x": x.ravel(), "cov": cov}


def _pass_banded(system, rhs):
    """The same by scipy.linalg's banded Cholesky (marginals: Takahashi on the band, or block columns)."""
    from scipy import linalg

    from visla_edu.smoother import _envelope

    n, b = system.num_blocks, system.diag.shape[1]
    t = {}
    ab, t["assemble"] = _seconds(lambda: _band(_sparse_system(system)))
    cb, t["factor"] = _seconds(linalg.cholesky_banded, ab, lower=True)
    x, t["solve"] = _seconds(linalg.cho_solve_banded, (cb, True), rhs.ravel())
    cov, t["marginals_takahashi"] = _seconds(lambda: _envelope.inverse_diagonal(_band_blocks(cb, n, b)))
    columns, t["marginals_block_columns"] = _block_columns(lambda i: _banded_column(cb, b, i), n)
    return t, {"x": x, "cov": cov, "columns": columns, "bandwidth": ab.shape[0] - 1}


def _pass_splu(system, rhs):
    """The same by scipy.sparse's SuperLU (minimum degree on A^T + A; marginals by block columns)."""
    from scipy.sparse import linalg as sparse_linalg

    n, b = system.num_blocks, system.diag.shape[1]
    t = {}
    S, t["assemble"] = _seconds(_sparse_system, system)
    lu, t["factor"] = _seconds(sparse_linalg.splu, S, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                               options={"SymmetricMode": True})
    x, t["solve"] = _seconds(lu.solve, rhs.ravel())
    columns, t["marginals_block_columns"] = _block_columns(lambda i: _lu_column(lu, n, b, i), n)
    return t, {"x": x, "columns": columns, "nnz": lu.L.nnz + lu.U.nnz}


def _relative(a, b):
    import numpy as np

    return float(f"{np.abs(a - b).max() / np.abs(b).max():.1e}")


def _summary(seconds, steps, reference=None):
    """Median seconds of each stage, ``step`` (assembly + factor + solve, what each Levenberg-Marquardt iteration
    pays), ``total`` (a step plus the fastest marginals), ``run_projection`` (``steps`` steps, then a factor and the
    marginals) and, given the envelope's summary, each of the three as a ratio to it (and ``total`` less the
    assembly, which no faster assembly of the sparse matrix could beat)."""
    import numpy as np

    t = {key: round(float(np.median([s[key] for s in seconds])), 3) for key in seconds[0]}
    marginals = min(v for k, v in t.items() if k.startswith("marginals"))
    t["step"] = round(t.get("assemble", 0) + t["factor"] + t["solve"], 3)
    t["total"] = round(t["step"] + marginals, 3)
    t["run_projection"] = round(steps * t["step"] + t.get("assemble", 0) + t["factor"] + marginals, 2)
    for key in ("step", "total", "run_projection") if reference else ():
        t[f"{key}_over_envelope"] = round(t[key] / reference[key], 2)
    if reference:  # a bound for any faster assembly of the sparse matrix
        t["total_without_assembly_over_envelope"] = round((t["total"] - t["assemble"]) / reference["total"], 2)
    return t


def case_solver(name, repeats=5):
    """The envelope Cholesky against scipy's banded Cholesky and sparse LU on one drive's reduced system.

    The repeats are interleaved (envelope, banded, LU, envelope, ...) so that a change of the
    machine's load falls on all three alike.
    """
    import numpy as np

    from visla_edu._blas import limit_blas_threads
    from visla_edu.smoother import _envelope

    system, rhs, steps = _reduced_system(name)
    band = _envelope.envelope_reach(system) - np.arange(system.num_blocks)
    out = {"pose_blocks": system.num_blocks, "landmark_terms": len(system.lo),
           "longest_track_frames": int((system.hi - system.lo).max() + 1), "band_blocks_max": int(band.max()),
           "band_blocks_median": float(np.median(band)), "smoother_steps": steps, "repeats": repeats}
    passes = {"envelope": _pass_envelope, "scipy_banded": _pass_banded, "scipy_splu": _pass_splu}
    seconds, last = {key: [] for key in passes}, {}
    with limit_blas_threads(1):  # as the smoother runs
        for _ in range(repeats):
            for key, one_pass in passes.items():
                t, last[key] = one_pass(system, rhs)
                seconds[key].append(t)
    env, banded, lu = last["envelope"], last["scipy_banded"], last["scipy_splu"]
    out["bandwidth_scalars"], out["splu_nnz"] = banded["bandwidth"], lu["nnz"]
    out["envelope"] = _summary(seconds["envelope"], steps)
    out["scipy_banded"] = {**_summary(seconds["scipy_banded"], steps, out["envelope"]),
                           "solve_vs_envelope": _relative(banded["x"], env["x"]),
                           "takahashi_vs_envelope": _relative(banded["cov"], env["cov"]),
                           "block_columns_vs_envelope": _relative(banded["columns"][1], env["cov"][banded["columns"][0]])}
    out["scipy_splu"] = {**_summary(seconds["scipy_splu"], steps, out["envelope"]),
                         "solve_vs_envelope": _relative(lu["x"], env["x"]),
                         "block_columns_vs_envelope": _relative(lu["columns"][1], env["cov"][lu["columns"][0]])}
    return out


RUNNERS = {"03": case_03, "03-window": case_03_window, "0020": case_0020,
           "0020-noisy": lambda trace: case_0020(trace, noisy=True), "objective": case_objective, "10": case_10,
           "10-outliers": case_10_outliers, "sim": case_sim, "solver-03": lambda _trace: case_solver("03"),
           "solver-10": lambda _trace: case_solver("10")}
NEEDS = {"03": "03.npz", "03-window": "03.npz", "0020": "kitti_odometry_06_poses.txt",
         "0020-noisy": "kitti_odometry_06_poses.txt", "objective": "kitti_odometry_06_poses.txt",
         "10": "10_imu_only.npz", "10-outliers": "10_imu_only.npz", "sim": None, "solver-03": "03.npz",
         "solver-10": "10_imu_only.npz"}


def _available(case):
    from visla_edu import data

    need = NEEDS[case]
    if need is None:
        return True
    try:
        return (data.data_dir() / need).is_file()
    except (FileNotFoundError, ValueError):
        return False


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    parser.add_argument("--tracemalloc", action="store_true", help="also report tracemalloc's peak (slower)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(RUNNERS[args.child](args.tracemalloc)))
        return
    for case in args.cases:
        if not _available(case):
            print(f"{case:11s} skipped: {NEEDS[case]} not in the data directory ({os.environ.get('VISLA_EDU_DATA')})")
            continue
        command = [sys.executable, str(Path(__file__).resolve()), "--child", case] + \
            (["--tracemalloc"] if args.tracemalloc else [])
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        wall = time.perf_counter() - start
        if done.returncode:
            print(f"{case:11s} failed:\n{done.stderr[-2000:]}")
            continue
        figures = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{case:11s} whole process {wall:.1f} s")
        print(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
