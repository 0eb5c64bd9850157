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
# bench name -> (estimator registry name, paper case: MHE case 1-4 or "ekf-rls"); the MHE/EKF cases set which
# parameters are augmented (1: theta, 3: theta, B, C, E).
BENCH_CASES: dict[str, tuple[str, int | str]] = {
    "mhe-theta": ("mhe", 1),
    "mhe-all": ("mhe", 3),
    "mhe-paper-theta": ("mhe-paper", 1),
    "mhe-paper-all": ("mhe-paper", 3),
    "mhe-literal-theta": ("mhe-literal", 1),
    "ekf-theta": ("ekf", 1),
    "ekf-all": ("ekf", 3),
    "ekf-rls": ("ekf-rls", "ekf-rls"),
}


def bench_estimators(repeats: int = 3, seed: int = 0) -> dict[str, dict[str, float]]:
    """Time ``update`` of each estimator over its paper case.

    :param repeats: runs over the case per estimator (a fresh ``reset`` each time).
    :param seed: noise seed of the generated logs.
    :return: ``{name: {"mean_us", "max_us", "cpu_mean_us", "updates"}}``.
    """
    from estimators.registry import get_estimator
    from estimators.scenarios import ekf_rls_scenario, mhe_case

    if int(repeats) != repeats or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    result = {}
    for name, (estimator, case) in BENCH_CASES.items():
        pc = ekf_rls_scenario(noisy=True, seed=seed) if case == "ekf-rls" else mhe_case(case, seed=seed)
        entry = get_estimator(estimator)
        est = entry.make(estimated=pc.estimated)
        log = pc.log
        cols = [np.asarray(getattr(log, c)) for c in est.measurement_columns]
        Y = np.column_stack(cols)
        U = np.asarray(log.T_b)
        skip = HORIZON_WARMUP if entry.family == "mhe" else 0
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
