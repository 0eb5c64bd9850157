"""Whether a quarter-car log's data show its answer: the true model, at its TRUE parameters (no fit) and judged with
the TRUE noise levels the source drew (not the tool's estimate), put through the diagnosis' own significance test
against the nominal model the tool calibrated.

The noise levels are given per logged channel as the white-noise standard deviation at the log's rate that carries
the same low-frequency power (a channel low-passed or interpolated by a logger: its std times the square root of
its integrated autocorrelation time, :mod:`validation.true_noise`), the form in which the diagnosis normalises a
filtered channel. The log's prepared data are rescaled to those levels: the nominal model is re-scored at its own
per-fold roads (nothing refitted) and the true model is scored on the same windows. A nominal log always counts as
shown (the answer ``none`` needs no evidence).

Whether the data tell the answer from the other library effects is a second question
(:func:`alternative_oracle`): the true model against the best other effect the diagnosis fitted, refitted at the
true noise levels.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

__all__ = ["alternative_oracle", "effect_oracle", "nominal_with_noise", "true_model_fit", "true_model_oracle",
           "with_noise"]


def with_noise(d, noise: dict[str, float]):
    """The prepared log ``d`` with its channels' noise levels replaced by ``noise`` (channel -> std, SI units).

    :raises ValueError: when ``noise`` misses a logged channel.
    """
    missing = [c for c in d.channels if c not in noise]
    if missing:
        raise ValueError(f"true noise level missing for channel(s) {', '.join(missing)}")
    return replace(d, sigma={c: float(noise[c]) for c in d.channels})


def true_model_fit(effects: dict[str, dict], road: dict, d):
    """The true model scored on the prepared log ``d`` (no fit): the true road and every effect at its true
    parameters, held out on every window as the candidates are.

    :param effects: effect name -> its true parameters (registry names, SI units), in the model's order.
    :param road: the true road, keys ``B, C, E, theta``.
    """
    from fricenv.effects import registry
    from fricenv.gap.quarter_car.fitting import score
    from fricenv.gap.quarter_car.params import ROAD_NAMES, param_names

    names = list(effects)
    x = np.array([road[k] for k in ROAD_NAMES] + [effects[e][k] for e in names for k in registry.get(e).param_names],
                 dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return score("+".join(names), names, param_names(names), x, d, 0.0)


def nominal_with_noise(dg, noise: dict[str, float]):
    """(the prepared log at the true noise levels, the tool's calibrated nominal model re-scored there at its own
    per-fold roads)."""
    from fricenv.gap.quarter_car.candidates import without_effects

    d = with_noise(dg.data, noise)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return d, without_effects(dg.nominal, d)


def true_model_oracle(effects: dict[str, dict], road: dict, dg, cfg, noise: dict[str, float]) -> dict:
    """The oracle of a library-effect log, at the true noise levels:

    - ``detectable``: the true model passes the diagnosis' significance rule
      (:func:`fricenv.gap.quarter_car.verdict.significant`: over the calibrated nominal model, and over its own road
      with the effects switched off); if not, no tool could name the effect from these data;
    - ``true_explains``: it closes the share of the gap the verdict rule asks of an effect
      (:func:`fricenv.gap.quarter_car.verdict.explains`).

    :param effects: effect name -> true parameters (registry names, SI units).
    :param road: the true road, keys ``B, C, E, theta``; :param dg: the log's diagnosis.
    :param cfg: the diagnosis settings; :param noise: the true noise std per logged channel.
    :return: ``{"detectable", "true_explains", "z_true"}`` (the true model's paired z there).
    """
    from fricenv.gap.quarter_car.candidates import test_against
    from fricenv.gap.quarter_car.verdict import explains, significant

    d, nominal = nominal_with_noise(dg, noise)
    true = true_model_fit(effects, road, d)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        test_against(nominal, true, d)
    return {"detectable": bool(significant(true, nominal, cfg)), "true_explains": bool(explains(true, nominal, cfg)),
            "z_true": float(true.z_paired)}


def alternative_oracle(effects: dict[str, dict], road: dict, dg, cfg, noise: dict[str, float]) -> dict:
    """Whether a log's data tell its true effects from the best other library effect, at the true noise levels.

    The other effect is the one the diagnosis ranked first among the single effects not in the log (its held-out
    error); it is fitted again per fold at the true noise levels, from the diagnosis' fit, and cross-fitted as the
    candidates are. The data tell the two apart when the true model (true road, true parameters, not fitted) beats
    that fit by the diagnosis' paired test (``sig_z``). Where they do not, a tool that names the other effect reads
    the data as well as the truth does; the true model is not fitted, so "apart" is an upper bound of what a fit
    finds.

    :param effects: the log's effects, name -> true parameters (registry names, SI units).
    :param road: the true road, keys ``B, C, E, theta``; :param dg: the log's diagnosis.
    :param cfg: the diagnosis settings; :param noise: the true noise std per logged channel.
    :return: ``{"apart", "alternative", "z_apart"}`` (``apart`` True and the rest None where the diagnosis
        fitted no other single effect).
    """
    from fricenv.gap.quarter_car.candidates import fit_candidate
    from fricenv.gap.quarter_car.params import road_of
    from fricenv.gap.quarter_car.stats import cross_fitted, fold_data, paired_z

    others = [f for f in dg.candidates if "+" not in f.effect and f.effect not in effects and f.effect != "nominal"]
    if not others:
        return {"apart": True, "alternative": None, "z_apart": None}
    best = min(others, key=lambda f: f.adjusted_mse)
    d = with_noise(dg.data, noise)
    true = true_model_fit(effects, road, d)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fits = [fit_candidate([best.effect], road_of(x), fold_data(d, j), cfg, {best.effect: best.effect_params()})
                for j, x in enumerate(best.x_folds)]
        z = float(paired_z(cross_fitted(fits, d), true, d))
    return {"apart": bool(z > cfg.sig_z), "alternative": best.effect, "z_apart": z}


def effect_oracle(effects: dict[str, dict], road: dict, dg, cfg, noise: dict[str, float]) -> dict:
    """Both oracles of a one-effect log: :func:`true_model_oracle`, and where its data show the effect,
    :func:`alternative_oracle` (the arguments are theirs)."""
    out = true_model_oracle(effects, road, dg, cfg, noise)
    if out["detectable"]:
        out.update(alternative_oracle(effects, road, dg, cfg, noise))
    return out
