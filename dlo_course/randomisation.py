"""Randomisation of the rod's physical parameters: the fields of
:class:`~dlo_course.simulation.SimParams` scaled by factors, checked, or drawn in ranges.

It sits below the environment, beside ``SimParams``: ``DLOShapeEnv(randomize=...)`` draws
factors here at every reset that rebuilds the world (domain randomisation), and
:mod:`dlo_course.robustness` scales the training world by fixed factors (model mismatch).
It imports nothing from the package at run time (``SimParams`` only for type checking), so
neither PyBullet nor torch.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

if TYPE_CHECKING:
    from dlo_course.simulation import SimParams

PERTURBABLE = ("youngs_modulus", "mass", "damping", "edge_damping")
"""The :class:`~dlo_course.simulation.SimParams` fields that can be scaled by a factor.
``edge_damping`` is 0 by default (the authors' rod has no dampers), so a factor on it changes
nothing unless the base ``params`` give it a value, e.g. ``SimParams(edge_damping=1.0)``."""


# ------------------------------------------------------------------ model mismatch
def validate_factors(factors: Mapping[str, float]) -> dict[str, float]:
    """Check scaling factors and return them as a plain ``{name: float}`` dict.

    Raises:
        ValueError: for a name outside :data:`PERTURBABLE`, or a factor that is not a
            finite positive number (a rod with zero or negative stiffness or mass means
            nothing).
    """
    checked = {}
    for name, factor in dict(factors).items():
        if name not in PERTURBABLE:
            raise ValueError(f"unknown parameter {name!r}: perturb one of "
                             f"{', '.join(PERTURBABLE)}")
        try:
            value = float(factor)
        except (TypeError, ValueError):
            raise ValueError(f"the factor of {name} must be a number, got {factor!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"the factor of {name} must be a finite positive number "
                             f"(1 = the training value), got {factor!r}")
        checked[name] = value
    return checked


def scale_params(params: "SimParams", factors: Mapping[str, float]) -> "SimParams":
    """A copy of ``params`` (:class:`~dlo_course.simulation.SimParams`) with each named field
    multiplied by its factor, e.g. ``scale_params(SimParams(), {"mass": 0.7})`` for a rod 30%
    lighter. The factors are checked first (:func:`validate_factors`); no factors: ``params``
    itself."""
    factors = validate_factors(factors)
    if not factors:
        return params
    return params.with_(**{name: getattr(params, name) * factor
                           for name, factor in factors.items()})


# ------------------------------------------------------------------ domain randomisation
def validate_ranges(ranges: Mapping[str, Sequence[float]]) -> dict[str, tuple[float, float]]:
    """Check domain-randomisation ranges ``{name: (low, high)}`` of factors and return them
    as ``{name: (float, float)}``.

    Raises:
        ValueError: for an unknown name, a range that is not two numbers, a bound that is not
            a finite positive factor, or ``low > high``.
    """
    checked = {}
    for name, bounds in dict(ranges).items():
        try:
            low, high = (float(b) for b in bounds)
        except (TypeError, ValueError):
            raise ValueError(f"the range of {name} must be two factors [low, high], "
                             f"got {bounds!r}") from None
        validate_factors({name: low})
        validate_factors({name: high})
        if low > high:
            raise ValueError(f"the range of {name} is empty: low {low} > high {high}")
        checked[name] = (low, high)
    return checked


def draw_factors(ranges: Mapping[str, Sequence[float]], rng: np.random.Generator
                 ) -> dict[str, float]:
    """One draw of domain-randomisation factors: each factor uniform in its range.

    The names are taken in sorted order and each gets exactly one ``rng.uniform(low, high)``,
    so the same generator state always gives the same factors, whatever the order in which
    ``ranges`` was written. The ranges are checked first (:func:`validate_ranges`).
    """
    checked = validate_ranges(ranges)
    return {name: float(rng.uniform(*checked[name])) for name in sorted(checked)}


