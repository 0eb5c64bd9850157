"""Per-element model parameters of a batched quarter car with effects (:class:`ModelBatch`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np

from fricenv.effects import registry
from fricenv.plants import quarter_car as qc

__all__ = ["ModelBatch"]


@dataclass(frozen=True)
class ModelBatch:
    """Per-element model parameters of a batch: the road and every effect's parameters, switched off by default.

    All arrays have shape ``(n,)`` except ``road`` ``(n, 4)``. "Off" values (the registry's ``Param.off``):
    ``tau = 0``, ``delay = 0``, ``gain = 1``, ``sigma = 0``, ``r_eff = p.r``, ``t_change = inf``, ``c0 = c2 = 0``,
    ``fade = 0``, ``load = 0``, ``slide = 0``. The parameters of plug-in effects (registered with
    ``builtin=False``) live in ``extra``, by parameter name.
    """

    road: np.ndarray  # (B, C, E, theta) per element
    tau: np.ndarray  # brake lag [s]
    delay: np.ndarray  # brake delay [s]
    gain: np.ndarray  # brake gain [-]
    sigma: np.ndarray  # relaxation length [m]
    r_eff: np.ndarray  # rolling radius [m]
    t_change: np.ndarray  # friction change time [s]
    theta_after: np.ndarray  # theta after the change [-]
    c0: np.ndarray  # drag constant [N]
    c2: np.ndarray  # drag quadratic coefficient [N s^2/m^2]
    fade: np.ndarray = None  # brake fade coefficient [1/J] (out of library)
    load: np.ndarray = None  # load transfer per g [-] (out of library)
    slide: np.ndarray = None  # friction decay per unit sliding speed [s/m] (out of library)
    extra: dict = None  # plug-in effects' parameters: name -> (n,) array

    def __post_init__(self):
        n = len(self.tau)
        for f in _arrays():
            if getattr(self, f) is None:
                object.__setattr__(self, f, np.zeros(n))
        if self.extra is None:
            object.__setattr__(self, "extra", {})

    def __len__(self) -> int:
        return len(self.tau)

    def param(self, name: str) -> np.ndarray:
        """The (n,) values of an effect parameter by its registry name (built-in field or ``extra``)."""
        for entry in registry.REGISTRY.values():
            for q in entry.params:
                if q.name == name:
                    return self.extra[name] if q.batch_field is None else getattr(self, q.batch_field)
        raise KeyError(f"no effect parameter {name!r} in the registry")

    @classmethod
    def nominal(cls, road, n: int, p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> ModelBatch:
        """``n`` elements with no effect on ``road`` ((4,), (n, 4) or a :class:`MagicFormula`)."""
        road = np.array(qc.road_array(road, n), dtype=float)
        values: dict[str, np.ndarray] = {}
        extra: dict[str, np.ndarray] = {}
        for entry in registry.REGISTRY.values():
            for q in entry.params:
                off = np.array(np.broadcast_to(np.asarray(q.off_value(road, p), dtype=float), (n,)))
                if q.batch_field is None:
                    extra[q.name] = off
                else:
                    values.setdefault(q.batch_field, off)
        return cls(road=road, extra=extra, **values)

    @classmethod
    def from_effects(cls, road, effects: Sequence, p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> ModelBatch:
        """One element on ``road`` with the effect specs ``effects`` switched on (each name at most once)."""
        batch = cls.nominal(road, 1, p)
        names = [e.name for e in effects]
        if len(set(names)) != len(names):
            raise ValueError(f"each effect may appear once, got {names}")
        return batch.with_params({q.name: np.array([float(getattr(effect, q.name))])
                                  for effect in effects for q in registry.get(effect.name).params},
                                 [e.name for e in effects])

    def with_params(self, values: dict[str, np.ndarray], effects: Sequence[str]) -> ModelBatch:
        """A copy with the parameters ``values`` (name -> (n,) array) of the effects ``effects`` set."""
        updates: dict[str, np.ndarray] = {}
        extra = dict(self.extra)
        for name in effects:
            for q in registry.get(name).params:
                if q.name in values:
                    if q.batch_field is None:
                        extra[q.name] = values[q.name]
                    else:
                        updates[q.batch_field] = values[q.name]
        return replace(self, extra=extra, **updates)

    def with_element(self, i: int, element: ModelBatch) -> ModelBatch:
        """A copy whose element ``i`` is the one element of ``element`` (same plug-in parameters)."""
        def put(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            a = a.copy()
            a[i] = b[0]
            return a

        return ModelBatch(extra={k: put(v, element.extra[k]) for k, v in self.extra.items()},
                          **{f: put(getattr(self, f), getattr(element, f)) for f in _arrays()})

    @classmethod
    def stack(cls, batches: Sequence[ModelBatch]) -> ModelBatch:
        """Concatenate batches along the leading dimension."""
        extra = {k: np.concatenate([b.extra[k] for b in batches]) for k in batches[0].extra}
        return cls(extra=extra, **{f: np.concatenate([getattr(b, f) for b in batches]) for f in _arrays()})

    def repeat(self, k: int) -> ModelBatch:
        """Each element repeated ``k`` times consecutively (element i -> rows i*k .. i*k+k-1)."""
        return ModelBatch(extra={n: np.repeat(v, k, axis=0) for n, v in self.extra.items()},
                          **{f: np.repeat(getattr(self, f), k, axis=0) for f in _arrays()})


def _arrays() -> list[str]:
    """The array fields of :class:`ModelBatch` (all but ``extra``)."""
    return [f.name for f in fields(ModelBatch) if f.name != "extra"]
