"""Cost per update of each estimator over a paper case (not a timed test; the CLI hook lives elsewhere).

:func:`bench_estimators` runs every estimator over its paper case ``repeats`` times and reports the mean and the
worst wall-clock time of one ``update`` in microseconds, plus the mean process CPU time (what an update costs when
the machine is shared). The MHE's first N updates only buffer samples and are left out of its figures.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["BENCH_CASES", "bench_estimators"]

HORIZON_WARMUP = 10  # MHE updates that only buffer samples
# name -> (paper case, estimator factory key)
BENCH_CASES = {
    "mhe-theta": 1,
    "mhe-all": 3,
    "mhe-paper-theta": 1,
    "mhe-paper-all": 3,
    "mhe-literal-theta": 1,
    "ekf-theta": 1,
    "ekf-all": 3,
    "ekf-rls": "ekf-rls",
}


def _make(name: str, estimated):
    from estimators.ekf import QuarterCarEKF
    from estimators.ekf_rls import QuarterCarEkfRls
    from estimators.mhe import RegularizedMHE

    if name.startswith("mhe-paper"):  # the paper's MHE: hard dynamics, beta-weighted prior
        return RegularizedMHE(estimated=estimated, arrival="paper", model_error=None)
    if name.startswith("mhe-literal"):
        return RegularizedMHE(estimated=estimated, weighting="literal")
    if name.startswith("mhe"):
        return RegularizedMHE(estimated=estimated)
    if name.startswith("ekf-rls"):
        return QuarterCarEkfRls()
    return QuarterCarEKF(estimated=estimated)


def bench_estimators(repeats: int = 3, seed: int = 0) -> dict[str, dict[str, float]]:
    """Time ``update`` of each estimator over its paper case.

    :param repeats: runs over the case per estimator (a fresh ``reset`` each time).
    :param seed: noise seed of the generated logs.
    :return: ``{name: {"mean_us", "max_us", "cpu_mean_us", "updates"}}``.
    """
    from estimators.scenarios import ekf_rls_scenario, mhe_case

    if int(repeats) != repeats or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    result = {}
    for name, case in BENCH_CASES.items():
        pc = ekf_rls_scenario(noisy=True, seed=seed) if case == "ekf-rls" else mhe_case(case, seed=seed)
        est = _make(name, pc.estimated)
        log = pc.log
        cols = [np.asarray(getattr(log, c)) for c in est.measurement_columns]
        Y = np.column_stack(cols)
        U = np.asarray(log.T_b)
        skip = HORIZON_WARMUP if name.startswith("mhe") else 0
        wall, cpu = [], []
        for _ in range(int(repeats)):
            est.reset()
            for k in range(len(U)):
                t0, c0 = time.perf_counter(), time.process_time()
                est.update(Y[k], U[k])
                if k >= skip:
                    wall.append(time.perf_counter() - t0)
                    cpu.append(time.process_time() - c0)
        wall_us, cpu_us = np.asarray(wall) * 1e6, np.asarray(cpu) * 1e6
        result[name] = {"mean_us": float(wall_us.mean()), "max_us": float(wall_us.max()),
                        "cpu_mean_us": float(cpu_us.mean()), "updates": int(wall_us.size)}
    return result
