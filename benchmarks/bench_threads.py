"""Where a second thread pays: the numba objective kernel over (particles × poses) and LAPACK's
Cholesky over matrix sides, on one and on two threads, quiet and with one busy process per
core.  The thresholds robocal.backend uses (PARALLEL_MIN_WORK, BLAS_PARALLEL_SIDE) come from
this table.  Run: python benchmarks/bench_threads.py
"""

import time
import warnings

import numba
import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_limits

from robocal.bench.workloads import busy_cores
from robocal.calibration.fit.problem import Setup
from robocal.io.robotfile import load_robot
from robocal.model.parameters import ParameterSpace
from robocal.simulation import simulate


def per_call(fn, seconds=0.3):
    fn()
    start, n = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        fn()
        n += 1
    return (time.perf_counter() - start) / n


def kernel_rows(label):
    warnings.simplefilter("ignore")
    robot = load_robot("er10l-c10")
    space = ParameterSpace.of(robot)
    names = [n for n in space.names if not n.startswith(("base", "tool"))][:24]
    for poses in (32, 128, 512):
        prob = Setup(space, simulate(robot, poses, deviations="paper", seed=1).measurements, 1.0, 0.01).problem(names)
        for particles in (20, 80, 400):
            X = np.random.default_rng(0).normal(0, 1e-3, (particles, prob.n_params))
            times = {}
            for threads in (1, 2):
                numba.set_num_threads(threads)
                times[threads] = per_call(lambda: prob.objective(X, backend="numba"))  # noqa: B023
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
            print(f"{label:6s} kernel, work {poses * particles:7d}: 1 thread {times[1] * 1e3:8.3f} ms, "
                  f"2 threads {times[2] * 1e3:8.3f} ms")


def blas_rows(label):
    rng = np.random.default_rng(0)
    for n in (500, 1000, 2000, 4000):
        A = rng.normal(size=(n, n))
        K = A @ A.T + n * np.eye(n)
        times = {}
        for threads in (1, 2):
            with threadpool_limits(threads, user_api="blas"):
                times[threads] = per_call(lambda: scipy.linalg.cholesky(K, lower=True), 0.5)  # noqa: B023
        print(f"{label:6s} Cholesky {n:5d}: 1 thread {times[1] * 1e3:8.2f} ms, 2 threads {times[2] * 1e3:8.2f} ms")


def likelihood_rows(label):
    """The residual process's likelihood and gradient on 1000 points (as --model auto tunes it),
    beside its Cholesky factor and inverse alone, on one and on two BLAS threads."""
    from robocal.calibration.select.likelihood import MarginalLikelihood, standardise

    rng = np.random.default_rng(0)
    q = rng.uniform(-2, 2, (1000, 6))
    y = np.column_stack([np.sin(3 * q[:, 0]), np.cos(2 * q[:, 1]), q[:, 2]]) + rng.normal(0, 0.3, (1000, 3))
    objective = MarginalLikelihood(q, standardise(y))
    theta = np.log(np.r_[5.0, 0.3, 0.3, 3.0, 50.0, 50.0, 50.0, 0.4])
    times = {}
    for threads in (1, 2):
        with threadpool_limits(threads, user_api="blas"):
            times[threads] = per_call(lambda: objective(theta), 1.0)  # noqa: B023
    print(f"{label:6s} likelihood and gradient, 1000 points: 1 thread {times[1] * 1e3:8.2f} ms, "
          f"2 threads {times[2] * 1e3:8.2f} ms")


kernel_rows("quiet")
blas_rows("quiet")
likelihood_rows("quiet")
with busy_cores():
    kernel_rows("busy")
    blas_rows("busy")
    likelihood_rows("busy")
