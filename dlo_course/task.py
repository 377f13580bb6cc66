"""The paper's task in numbers, each defined once: how many nodes, when a goal counts as
reached, which thresholds Table I reports, and where each part sits in an observation.

Imports neither torch nor PyBullet (nor anything of the package), so that the command line,
the configurations and every layer of the library can use it.

The observation of ``DLOShape-v0`` (the paper's eq. (4)) for m selected nodes is a vector of
6 + 6m numbers (:func:`observation_size`)::

    [ tip position (3) | tip velocity (3) | P_c, current node positions (3m) | P_d, desired (3m) ]

:func:`split_observation` cuts one or a batch of them, NumPy arrays or torch tensors, into
those four parts; :class:`ObservationLayout` gives the slices, to write into a part.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

NODE_COUNTS: tuple[int, ...] = (2, 4, 6)
"""The numbers of selected mesh nodes the paper trains and tests (its three agents)."""

DEFAULT_N_NODES = 4
"""The node count of the library's functions and commands when none is given (the
environment, the demo, the controllers; a trained agent's own count wins when it has one).
The training presets name theirs."""

TABLE_THRESHOLDS: tuple[float, ...] = (0.05, 0.03)
"""The success thresholds (m) of the paper's Table I, in its column order."""

TRAIN_THRESHOLD = TABLE_THRESHOLDS[0]
"""The success threshold (m) the paper trains with, and the environment's default."""

TIP_DIM = 3
"""Components of the tip position, and of the tip velocity (and of the action)."""


def reached(distance: Any, threshold: float) -> Any:
    """Whether a mean node distance (m) counts as reaching the goal: strictly below
    ``threshold``. The one success rule: the environment's termination and ``is_success``,
    hindsight relabelling and the evaluation all use it. Works elementwise on arrays (a bool
    array) and on a float (a NumPy bool; wrap it in ``bool()`` for a Python one)."""
    return distance < threshold


def observation_size(n_nodes: int) -> int:
    """Components of an observation for ``n_nodes`` selected nodes: 6 + 6m (18, 30, 42)."""
    return 2 * TIP_DIM + 6 * int(n_nodes)


def nodes_of_observation_size(size: int) -> int | None:
    """The node count whose observations have ``size`` components, among
    :data:`NODE_COUNTS`; None for any other size."""
    for n_nodes in NODE_COUNTS:
        if observation_size(n_nodes) == size:
            return n_nodes
    return None


@dataclass(frozen=True)
class ObservationLayout:
    """Where each part sits in an observation of ``n_nodes`` selected nodes (slices of the
    last axis)."""

    n_nodes: int

    @property
    def size(self) -> int:
        return observation_size(self.n_nodes)

    @property
    def tip(self) -> slice:
        return slice(0, TIP_DIM)

    @property
    def tip_velocity(self) -> slice:
        return slice(TIP_DIM, 2 * TIP_DIM)

    @property
    def current(self) -> slice:
        """P_c: 6 .. 6 + 3m."""
        return slice(2 * TIP_DIM, 2 * TIP_DIM + 3 * self.n_nodes)

    @property
    def desired(self) -> slice:
        """P_d: 6 + 3m .. 6 + 6m."""
        return slice(2 * TIP_DIM + 3 * self.n_nodes, self.size)

    def check(self, obs: Any) -> None:
        """ValueError unless the last axis of ``obs`` has :attr:`size` components."""
        if obs.shape[-1] != self.size:
            raise ValueError(f"an observation of {self.n_nodes} nodes has {self.size} "
                             f"components, got {obs.shape[-1]}")


class ObservationParts(NamedTuple):
    """An observation's four parts (views, not copies), for observations of shape (..., 6 + 6m):
    ``tip`` and ``tip_velocity`` (..., 3), ``current`` (P_c) and ``desired`` (P_d) (..., m, 3)."""

    tip: Any
    tip_velocity: Any
    current: Any
    desired: Any


def split_observation(obs: Any, n_nodes: int) -> ObservationParts:
    """Cut observations (..., 6 + 6m), a NumPy array or a torch tensor, into their parts:
    tip position (..., 3) in m, tip velocity (..., 3) in m/s, P_c and P_d (..., m, 3) in m.

    The parts are views of ``obs`` (writing into them writes into ``obs``) of its type and
    dtype. Raises ValueError if the last axis is not 6 + 6m long."""
    layout = ObservationLayout(int(n_nodes))
    layout.check(obs)
    lead = tuple(obs.shape[:-1])
    return ObservationParts(obs[..., layout.tip], obs[..., layout.tip_velocity],
                            obs[..., layout.current].reshape(*lead, layout.n_nodes, 3),
                            obs[..., layout.desired].reshape(*lead, layout.n_nodes, 3))
