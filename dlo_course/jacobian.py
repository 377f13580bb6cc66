"""A classical baseline: model-free shape servoing with an online deformation Jacobian.

Before deep RL, 3D shape control of soft objects was done by *visual servoing* with a
deformation Jacobian estimated online (Navarro-Alarcon et al., the family of methods the paper
cites for 3D control of small deformations). No model of the rod is needed: the controller
only assumes that, near the current shape, the selected nodes move linearly with the tip,

    dP = J du,       P = [P_c,1 | ... | P_c,m] (3m,),  u = the tip position (3,),  J (3m, 3),

and learns J from what it sees:

1. **Probing** (:func:`jacobian_from_probes`): at the start of an episode the tip makes one
   small move along each axis; the observed node displacements against the observed tip
   displacements give a first J by finite differences.
2. **Broyden's rank-one update** (:func:`broyden_update`): after every later action, J is
   corrected, as little as possible, so that it explains the displacement just observed.
3. **Damped least squares** (:func:`damped_least_squares_step`): the tip move that best brings
   the nodes towards their goal according to J, ``du = (J^T J + lambda^2 I)^-1 J^T (P_d -
   P_c)``; the damping keeps the move small where J is nearly singular (3m equations, only 3
   unknowns: the goal is generally out of reach, and least squares takes the best compromise).

:class:`JacobianController` puts the three together behind the interface the evaluation
protocol needs (:class:`dlo_course.evaluation.Controller`), so ``dlo-course evaluate
--controller jacobian`` scores it exactly as a trained agent.

Why it should struggle here: the model is quasi-static (the nodes are where the tip puts
them), while in the default ``"code"`` time an action lasts 3 ms of physics and the rod keeps
swinging for tens of actions after a move (docs/design.md, "Time per action"). The probes and
the updates therefore see the rod's *first 3 ms* of response, mixed with the echo of earlier
moves.
"""

from __future__ import annotations

import numpy as np

from dlo_course.evaluation import Controller
from dlo_course.task import split_observation


# ------------------------------------------------------------------ the three pieces
def jacobian_from_probes(tip_moves, node_moves) -> np.ndarray:
    """A first Jacobian by finite differences from a few probing moves.

    Probe k moved the tip by ``tip_moves[k]`` and the nodes by ``node_moves[k]``. With the
    linear model ``node_moves[k] = J tip_moves[k]`` for every k, J is the least-squares
    solution of ``tip_moves @ J.T = node_moves``: exact when there are 3 independent probes
    and the model holds (e.g. one move per axis: column i of J is the nodes' displacement per
    metre of tip motion along axis i).

    Args:
        tip_moves: (k, 3) observed tip displacements (m), k >= 3, spanning the 3 axes.
        node_moves: (k, 3m) observed displacements of the stacked node positions (m).

    Returns:
        J: (3m, 3) float64.

    Raises:
        ValueError: when the probes do not span the 3 axes (J would be undetermined).
    """
    tip_moves = np.asarray(tip_moves, dtype=np.float64)
    node_moves = np.asarray(node_moves, dtype=np.float64)
    if tip_moves.ndim != 2 or tip_moves.shape[1] != 3 or node_moves.ndim != 2 \
            or len(node_moves) != len(tip_moves):
        raise ValueError(f"expected tip_moves (k, 3) and node_moves (k, 3m), got "
                         f"{tip_moves.shape} and {node_moves.shape}")
    if np.linalg.matrix_rank(tip_moves) < 3:
        raise ValueError("the probing moves must span the 3 axes of the tip")
    solution, *_ = np.linalg.lstsq(tip_moves, node_moves, rcond=None)  # (3, 3m) = J^T
    return solution.T


def broyden_update(jacobian, tip_move, node_move, gain: float = 1.0,
                   min_move: float = 0.0) -> np.ndarray:
    """Broyden's rank-one correction of a Jacobian from one observed move.

    The smallest change of J (in the Frobenius norm) after which J predicts the observed
    move exactly (the *secant condition* ``J_new du = dP``), taken ``gain`` of the way:

        J_new = J + gain * (dP - J du) du^T / (du^T du).

    J changes only along ``du``: what it says about other directions of the tip is kept.

    Args:
        jacobian: (3m, 3) current estimate J.
        tip_move: (3,) observed tip displacement du (m).
        node_move: (3m,) observed displacement dP of the stacked node positions (m).
        gain: in (0, 1]; below 1 the correction is partial, which averages out noisy moves.
        min_move: moves with ``|du|`` at or below this (m) leave J as it is: dividing by a
            tiny ``du^T du`` would turn noise into a huge correction.

    Returns:
        J_new: (3m, 3) float64 (a new array; the input is not modified).
    """
    jacobian = np.asarray(jacobian, dtype=np.float64)
    du = np.asarray(tip_move, dtype=np.float64).reshape(3)
    dp = np.asarray(node_move, dtype=np.float64).reshape(-1)
    norm2 = float(du @ du)
    if norm2 == 0.0 or np.sqrt(norm2) <= min_move:
        return jacobian.copy()
    surprise = dp - jacobian @ du  # what J failed to predict, (3m,)
    return jacobian + gain * np.outer(surprise, du) / norm2


def damped_least_squares_step(jacobian, error, damping: float) -> np.ndarray:
    """The tip move that best reduces a shape error according to J, damped.

    Minimises ``|J du - e|^2 + lambda^2 |du|^2``, whose solution is

        du = (J^T J + lambda^2 I)^-1 J^T e.

    With lambda = 0 it is the ordinary least-squares move; a larger lambda gives a shorter
    move, and a well-behaved one where J is nearly singular (Levenberg-Marquardt).

    Args:
        jacobian: (3m, 3) J.
        error: (3m,) the stacked shape error e = P_d - P_c (m).
        damping: lambda >= 0, in the units of J (metres of node motion per metre of tip
            motion).

    Returns:
        du: (3,) float64 tip displacement (m).
    """
    jacobian = np.asarray(jacobian, dtype=np.float64)
    error = np.asarray(error, dtype=np.float64).reshape(-1)
    if damping < 0:
        raise ValueError(f"damping must be >= 0, got {damping}")
    normal = jacobian.T @ jacobian + damping ** 2 * np.eye(jacobian.shape[1])
    return np.linalg.solve(normal, jacobian.T @ error)


# ------------------------------------------------------------------ the controller
class JacobianController(Controller):
    """Shape servoing with a probed, Broyden-updated Jacobian, as a policy for evaluation.

    An episode (after :meth:`reset`):

    * actions 1-3 are the **probes**: a move of ``probe_size`` metres along x, then y, then z.
      Each probe goes in the direction of the goal along its axis (the mean of P_d - P_c), so
      that it is not wasted, unless that would leave the tip workspace. They count among the
      episode's 30 actions, as every action of a trained agent does: the comparison stays fair
      and the protocol unchanged. (The alternative, probing before the episode starts, would
      give the controller free actions and a rod at rest that no agent gets.)
    * after the third probe's observation, J comes from :func:`jacobian_from_probes`; every
      later action first corrects J with :func:`broyden_update` from the move just observed,
      then takes ``gain`` times the :func:`damped_least_squares_step` towards the goal,
      shortened to at most ``max_move`` metres and converted into a normalised action.

    The moves it learns from are the *observed* ones (tip positions and P_c in consecutive
    observations), not the commanded ones: the arm lags its target and the workspace clips it.

    Args:
        n_nodes: m, the selected nodes in the observation (2, 4 or 6).
        probe_size: length (m) of each probing move.
        damping: lambda of the damped least-squares step.
        gain: fraction of the least-squares move taken per action.
        max_move: the longest tip move (m) per action; at most one action's reach, 0.06 m.
        broyden_gain: ``gain`` of :func:`broyden_update`.
        broyden_min_move: tip moves (m) too small to learn from (:func:`broyden_update`).

    The defaults are slow and cautious on purpose: the rod keeps moving for many actions
    after the tip stops, so a controller that takes the full least-squares move every action
    overshoots and then swings. Of six settings tried on the goals of the first 6 of the 20
    benchmark episodes (``benchmarks/results/jacobian/README.md``), this one did best; it
    was not tuned further.
    """

    def __init__(self, n_nodes: int, probe_size: float = 0.02, damping: float = 0.3,
                 gain: float = 0.5, max_move: float = 0.01, broyden_gain: float = 0.3,
                 broyden_min_move: float = 0.002) -> None:
        if n_nodes < 1:
            raise ValueError(f"n_nodes must be positive, got {n_nodes}")
        if not (probe_size > 0 and max_move > 0 and gain > 0 and damping >= 0):
            raise ValueError("probe_size, max_move and gain must be positive, damping >= 0")
        self.n_nodes = n_nodes
        self.probe_size = probe_size
        self.damping = damping
        self.gain = gain
        self.max_move = max_move
        self.broyden_gain = broyden_gain
        self.broyden_min_move = broyden_min_move
        # The robot's constants; bind() replaces these defaults with the environment's.
        from dlo_course.simulation import SimParams  # imports PyBullet: only when needed

        params = SimParams()
        self.metres_per_action = params.v_max * params.action_duration
        self.workspace: tuple[np.ndarray, np.ndarray] | None = None
        self.reset()

    def bind(self, env) -> None:
        """Read the robot's constants from a :class:`~dlo_course.env.DLOShapeEnv` (or its
        wrapper): metres of tip motion per unit action and the tip workspace. Never the goal:
        the controller sees the goal only through the observation, as an agent does."""
        env = env.unwrapped
        if env.n_nodes != self.n_nodes:
            raise ValueError(f"the controller is for {self.n_nodes} nodes, the environment "
                             f"has {env.n_nodes}")
        self.metres_per_action = env.params.v_max * env.params.action_duration
        low, high = env.scene.workspace
        self.workspace = (np.array(low, dtype=np.float64), np.array(high, dtype=np.float64))

    def reset(self, obs=None) -> None:
        """Forget the last episode: its Jacobian and its probes."""
        self.jacobian: np.ndarray | None = None
        self._probe_tip: list[np.ndarray] = []
        self._probe_nodes: list[np.ndarray] = []
        self._previous: tuple[np.ndarray, np.ndarray] | None = None  # (tip, P_c) last seen

    def split(self, obs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(tip (3,), P_c (3m,), P_d (3m,)) of an observation, float64 (DLOShapeEnv's
        layout: tip, tip velocity, P_c, P_d)."""
        parts = split_observation(np.asarray(obs, dtype=np.float64).reshape(-1), self.n_nodes)
        return parts.tip, parts.current.reshape(-1), parts.desired.reshape(-1)

    def act(self, obs) -> np.ndarray:
        """The next action, (3,) float32 in [-1, 1], for one observation (6 + 6m,)."""
        tip, current, desired = self.split(obs)
        if self._previous is not None:
            tip_move, node_move = tip - self._previous[0], current - self._previous[1]
            if self.jacobian is None:
                self._probe_tip.append(tip_move)
                self._probe_nodes.append(node_move)
                if len(self._probe_tip) == 3:
                    self.jacobian = self._first_jacobian()
            else:
                self.jacobian = broyden_update(self.jacobian, tip_move, node_move,
                                               self.broyden_gain, self.broyden_min_move)
        self._previous = (tip, current)

        if self.jacobian is None:
            move = self._probe(len(self._probe_tip), tip, current, desired)
        else:
            move = self.gain * damped_least_squares_step(self.jacobian, desired - current,
                                                         self.damping)
            length = float(np.linalg.norm(move))
            if length > self.max_move:  # shorten, keeping the direction
                move *= self.max_move / length
        action = move / self.metres_per_action
        largest = float(np.max(np.abs(action)))
        if largest > 1.0:  # the action box clips each axis; scaling keeps the direction
            action /= largest
        return action.astype(np.float32)

    # ---------------------------------------------------------------- helpers
    def _probe(self, axis: int, tip, current, desired) -> np.ndarray:
        """The tip move of probe ``axis`` (0, 1, 2): towards the goal along that axis,
        unless that would leave the workspace."""
        wanted = float(np.mean((desired - current).reshape(-1, 3)[:, axis]))
        sign = 1.0 if wanted >= 0 else -1.0
        if self.workspace is not None:
            low, high = self.workspace
            if not low[axis] <= tip[axis] + sign * self.probe_size <= high[axis]:
                sign = -sign
        move = np.zeros(3)
        move[axis] = sign * self.probe_size
        return move

    def _first_jacobian(self) -> np.ndarray:
        """J from the probes; if the tip barely moved along an axis (an arm stuck at the
        workspace's edge), that column stays 0 rather than a division by almost nothing."""
        tip_moves, node_moves = np.array(self._probe_tip), np.array(self._probe_nodes)
        try:
            return jacobian_from_probes(tip_moves, node_moves)
        except ValueError:
            jacobian = np.zeros((node_moves.shape[1], 3))
            for k, du in enumerate(tip_moves):
                jacobian = broyden_update(jacobian, du, node_moves[k], 1.0,
                                          self.broyden_min_move)
            return jacobian


CONTROLLERS = {"jacobian": JacobianController}
"""The classical controllers by name (``dlo-course evaluate --controller NAME``): each is
built with the number of nodes alone, its other settings at their defaults."""
