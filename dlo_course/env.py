"""``DLOShape-v0``: the paper's task as a Gymnasium environment (Sections IV-E and V).

Build it with :func:`make_env` (or ``gymnasium.make("DLOShape-v0", ...)``, the same thing):
the library builds every one of its rod environments that way, so they all carry Gymnasium's
usual wrappers and their step limit as a ``TimeLimit``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from dlo_course.database import resolve_goals
from dlo_course.mesh import selected_nodes
from dlo_course.randomisation import draw_factors, scale_params, validate_ranges
from dlo_course.simulation import RodScene, SimParams, sim_params
from dlo_course.task import DEFAULT_N_NODES, TRAIN_THRESHOLD, ObservationLayout, reached

ENV_ID = "DLOShape-v0"
MAX_EPISODE_STEPS = 300
"""The registered step limit: the paper's training episode (its test episodes: 30)."""


def make_env(max_episode_steps: int | None = MAX_EPISODE_STEPS, **kwargs: Any) -> gym.Env:
    """``DLOShape-v0`` through ``gymnasium.make``: the one way the library builds it.

    Args:
        max_episode_steps: truncate an episode after this many actions (Gymnasium's
            ``TimeLimit``); ``None``: no limit.
        **kwargs: the arguments of :class:`DLOShapeEnv`.

    Returns:
        The wrapped environment; ``env.unwrapped`` is the :class:`DLOShapeEnv` (its
        ``scene``, ``goal_set``, ``threshold``...).
    """
    # gymnasium.make's -1 means "no TimeLimit at all" (None would mean the registered 300).
    return gym.make(ENV_ID, max_episode_steps=-1 if max_episode_steps is None
                    else max_episode_steps, **kwargs)


class DLOShapeEnv(gym.Env):
    """Shape control of a deformable linear object by a Panda.

    ## Description

    A Franka Panda holds the top of a 1.55 m tetrahedral FEM rod whose bottom is fixed to the
    ground (Zakaria et al., CASE 2022). Each episode draws a goal: desired positions P_d of m
    selected mesh nodes (m = 2, 4 or 6), a shape the rod took in a deformation database. The
    agent moves the gripper so that the current positions P_c of those nodes reach P_d.

    ## Action Space

    ``Box(-1, 1, (3,), float32)``: the tip's Cartesian velocity as a fraction of
    ``v_max`` = 1 m/s. It is integrated over ``action_duration`` = 0.06 s into a tip target,
    clipped to the tip workspace box, and reached through the Panda's inverse kinematics
    with the tip orientation held. Out-of-range actions are clipped; non-finite ones raise
    ``ValueError``.

    ## Observation Space

    ``Box(float32)`` of size 6 + 6m (18, 30 or 42), the paper's eq. (4), clipped to generous
    finite bounds (:func:`dlo_course.task.split_observation` cuts it into its parts):

    =========  ===========================  ======  ==========
    index      what                         unit    bound
    =========  ===========================  ======  ==========
    0-2        tip position (world frame)   m       +-10
    3-5        tip linear velocity          m/s     +-100
    6..6+3m    P_c, current node positions  m       +-10
    6+3m..     P_d, desired node positions  m       +-10
    =========  ===========================  ======  ==========

    ## Rewards

    The paper's eq. (5): ``r = -mean_i ||P_c,i - P_d,i||`` (metres) after every action.

    ## Starting State

    The initial scene (the arm in the authors' posture, the rod straight) rebuilt, or with
    ``reset(options={"reinitialize": False})`` the rod's current shape kept (the paper's test
    "without reinitialization"); a goal drawn uniformly from the goal set, or
    ``options={"goal_index": i}``. Every reset then lets the world settle as the authors'
    reset did: ``params.reset_steps(n_nodes, rebuilt)`` physics steps (12 + m, plus 8 after a
    rebuild).

    ## Episode End

    * Termination: the mean node distance falls below ``threshold``.
    * Truncation: the ``TimeLimit`` of :func:`make_env` (``max_episode_steps``, 300 when
      registered: the paper's training episode), or a simulation that blew up; then ``info``
      says ``simulation_unstable``, the agent gets the last sane observation, and the next
      reset rebuilds the world.

    ``info``: ``distance``, ``is_success``, ``tip_position``, ``goal_index``,
    ``simulation_unstable``.

    ## Arguments

    * ``n_nodes``: number of selected nodes, 2, 4 or 6 (the paper's three trainings,
      :data:`dlo_course.task.NODE_COUNTS`); by default
      :data:`dlo_course.task.DEFAULT_N_NODES` (4).
    * ``goals``: where the desired shapes come from
      (:func:`dlo_course.database.resolve_goals`): "small" or "large" (every record of the
      paper's deformation databases), "small-test" or "large-test" (the goals the paper's
      Table I was measured on), a database or goal file path, or an array (K, n_nodes, 3) of
      desired node positions in metres, world frame.
    * ``threshold``: success distance (m); the paper trains at 0.05 and tests at 0.05 and 0.03
      (:data:`dlo_course.task.TRAIN_THRESHOLD`, :data:`dlo_course.task.TABLE_THRESHOLDS`).
    * ``render_mode``: None, "rgb_array" (an image of robot and rod, P_c blue and P_d red
      crosses) or "human" (PyBullet's GUI; needs a display). Without one, "human" raises a
      ``RuntimeError`` here, at ``gymnasium.make``
      (:func:`dlo_course.simulation.check_display`), where PyBullet itself would end the
      interpreter. So gymnasium's ``check_env`` with its render check passes where there is a
      screen and fails with that error on a headless machine, since it makes the environment
      in every render mode: there, call it with ``skip_render_check=True``.
    * ``time_mode``: physics time per action, "code" (3 ms, the authors' code; the default) or
      "paper" (0.06 s, 20 times the compute): a shortcut for ``params.with_(time_mode=...)``,
      and the one to use; given, it overrides ``params.time_mode``.
    * ``params``: every physical and timing parameter (:class:`SimParams`), the paper's and
      the authors' values by default.
    * ``randomize``: domain randomisation, off by default (None or ``{}``). A dict ``{name:
      [low, high]}`` of factor ranges for fields of ``params`` (Young's modulus, mass,
      damping, edge damping: :data:`dlo_course.randomisation.PERTURBABLE`), e.g.
      ``{"youngs_modulus": [0.7, 1.3]}``: every reset that rebuilds the world draws each
      factor uniformly in its range and builds the rod with ``params`` scaled by them
      (:func:`dlo_course.randomisation.draw_factors`; the draw is in ``sim_factors``). The
      draws come from their own generator, seeded by ``reset(seed=...)``, so a seeded run is
      deterministic and gets the goals it would get without randomisation. A reset with
      ``reinitialize=False`` keeps the rod, and so its factors.

    ## Version History

    * v0 (this version). Decisions that change behaviour, each a parameter:

      - time per action: ``time_mode="code"`` by default, because the published numbers come
        from the authors' code, which advances 3 ms per action where the paper's text says
        0.06 s (``"paper"``);
      - goals: the default databases are recorded with the authors' sweep protocol (a
        snapshot 6 ms after every move of a continuous sweep), not the first round's settled
        protocol (``small_settled`` / ``large_settled``);
      - reset settling: every reset steps the world 12 + m times (20 + m after a rebuild)
        before the first observation, as the authors' reset did
        (``SimParams.reset_settle_steps``, ``rebuild_settle_steps``; 0 and 0 give the first
        round's behaviour);
      - the authors' rod: no edge dampers (``SimParams.edge_damping`` = 0; the course's rods
        had 1 N·s/m until issue 35), and the tip read as the last physics step left it,
        without forward kinematics, as the authors read it (docs/design.md, "The scene");
      - the step limit is only ``TimeLimit``'s: the environment no longer takes a
        ``max_episode_steps`` of its own.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(
        self,
        n_nodes: int = DEFAULT_N_NODES,
        goals: str | np.ndarray = "small",
        threshold: float = TRAIN_THRESHOLD,
        render_mode: str | None = None,
        time_mode: str | None = None,
        params: SimParams | dict[str, Any] | None = None,
        randomize: dict[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.node_ids = np.array(selected_nodes(n_nodes))
        self.n_nodes = n_nodes
        if not (np.isfinite(threshold) and threshold > 0):
            raise ValueError(f"threshold must be a positive distance in metres, got {threshold}")
        self.threshold = float(threshold)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.render_mode = render_mode
        # A dict of SimParams fields, so that JSON (--env-kwargs, config.json) can set them.
        params = sim_params(params)
        if time_mode is not None:
            params = params.with_(time_mode=time_mode)
        self.params = params
        # Domain randomisation (off by default): factors drawn at every rebuilding reset.
        self.randomize = validate_ranges(randomize or {})
        self.sim_factors: dict[str, float] = {}
        """The factors of the world in use (empty: the nominal ``params``)."""
        self._randomizer = np.random.default_rng()
        self.goal_set = resolve_goals(goals, n_nodes)

        # Generous finite bounds: positions within 10 m of the origin, tip speed below
        # 100 m/s. Observations are clipped to them, so they always lie in the space.
        layout = ObservationLayout(n_nodes)
        bound = np.full(layout.size, 10.0, dtype=np.float32)
        bound[layout.tip_velocity] = 100.0
        self.observation_space = spaces.Box(-bound, bound, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)

        self.scene = RodScene(params, gui=render_mode == "human")
        self.goal_index = -1
        self.goal = np.zeros((n_nodes, 3))
        self._last_obs: np.ndarray | None = None  # last sane observation, None before reset
        self._last_distance = np.nan
        self._fresh = True  # the scene is in its initial configuration, untouched
        self._broken = False  # the simulation blew up; only a rebuild recovers

    # -------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"reinitialize", "goal_index"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; "
                             "use 'reinitialize' and/or 'goal_index'")
        rebuilt = bool(options.get("reinitialize", True) or self._last_obs is None
                       or self._broken)
        if seed is not None:  # the randomiser's own stream: the goals stay as without it
            self._randomizer = np.random.default_rng([seed, 0xD0])
        if rebuilt:
            if self.randomize:
                self.sim_factors = draw_factors(self.randomize, self._randomizer)
                self.scene.params = scale_params(self.params, self.sim_factors)
                self.scene.build()
            elif not self._fresh:
                self.scene.build()
            self._broken = False
        self._fresh = False
        if "goal_index" in options:
            index = int(options["goal_index"])
            self._check_goal_index(index)
        else:
            index = int(self.np_random.integers(len(self.goal_set)))
        self.scene.step_physics(self.params.reset_steps(self.n_nodes, rebuilt))
        return self.set_goal(index)

    @property
    def random_episodes(self) -> bool:
        """True with domain randomisation: every rebuilt world is drawn anew, so two episodes
        towards the same goal from a rebuilt world differ (the evaluation then plays each
        one, and never forks one settled world for several: :mod:`dlo_course.snapshot`)."""
        return bool(self.randomize)

    def set_goal(self, index: int) -> tuple[np.ndarray, dict[str, Any]]:
        """Make ``goal_set[index]`` the goal without touching the simulation; returns the
        observation and info of the rod as it is, towards that goal, as ``reset`` does.

        The last part of every reset. On its own it lets one settled world serve several
        goals: the evaluation forks the process after one reset and gives each copy its goal
        (:mod:`dlo_course.snapshot`); the physics never depends on the goal."""
        self._check_goal_index(int(index))
        self.goal_index = int(index)
        self.goal = self.goal_set[self.goal_index]
        obs, distance = self._observe(self.scene.node_positions())
        self._last_obs, self._last_distance = obs, distance
        return obs, self._info(distance, unstable=False)

    def _check_goal_index(self, index: int) -> None:
        if not 0 <= index < len(self.goal_set):
            raise ValueError(f"goal_index {index} out of range 0..{len(self.goal_set) - 1}")

    def step(self, action):
        action = np.asarray(action, dtype=np.float64).reshape(-1)
        if action.shape != (3,):
            raise ValueError(f"action must have 3 components (tip velocity), got {action.shape}")
        if not np.all(np.isfinite(action)):
            raise ValueError(f"action must be finite, got {action}")
        if self._last_obs is None:
            raise RuntimeError("call reset() before step()")
        if self._broken:
            raise RuntimeError("the simulation blew up in this episode; call reset()")
        action = np.clip(action, -1.0, 1.0)

        self.scene.move_tip_to(self.scene.tip_target(action))

        nodes = self.scene.node_positions()
        if self.scene.is_unstable(nodes):
            # The agent never sees a NaN: it gets the last sane observation, the episode is
            # cut, and info says why. The next reset rebuilds the scene.
            self._broken = True
            info = self._info(self._last_distance, unstable=True)
            return self._last_obs.copy(), -self._last_distance, False, True, info

        obs, distance = self._observe(nodes)
        self._last_obs, self._last_distance = obs, distance
        terminated = bool(reached(distance, self.threshold))
        return obs, -distance, terminated, False, self._info(distance, False)

    def render(self):
        if self.render_mode != "rgb_array":
            return None  # "human": the GUI draws itself
        nodes = self.scene.node_positions()
        return self.scene.render(markers=((nodes[self.node_ids], (40, 80, 255)),
                                          (self.goal, (230, 30, 30))))

    def close(self) -> None:
        self.scene.close()

    def observation_reference(self) -> tuple[np.ndarray, np.ndarray]:
        """A fixed (offset, scale) per observation component, both (6 + 6m,) float32, such
        that ``(obs - offset) / scale`` is of order one. Used by DDPG's optional input
        normalisation (``DDPGConfig.normalize_obs``, not in the paper); see docs/design.md.

        * tip position: centre and half-widths of the tip workspace box;
        * tip velocity: 0 and the largest commanded tip speed, v_max * action_duration /
          physics time per action (1 m/s in "paper" time, 20 m/s in "code" time, where an
          action moves the tip up to 6 cm in 3 ms of physics);
        * P_c and P_d (the same for both, so that their difference keeps its meaning): the
          mean and standard deviation of the goal set, per node and axis (at least 1 cm).
        """
        low, high = self.scene.workspace
        prm = self.params
        speed = prm.v_max * prm.action_duration / prm.physics_time_per_action
        nodes_offset = self.goal_set.mean(axis=0).ravel()
        nodes_scale = np.maximum(self.goal_set.std(axis=0).ravel(), 0.01)
        offset = np.concatenate([(low + high) / 2, np.zeros(3), nodes_offset, nodes_offset])
        scale = np.concatenate([(high - low) / 2, np.full(3, speed), nodes_scale, nodes_scale])
        return offset.astype(np.float32), scale.astype(np.float32)

    # -------------------------------------------------------------- helpers
    def _observe(self, nodes: np.ndarray) -> tuple[np.ndarray, float]:
        tip, velocity = self.scene.tip_state()
        current = nodes[self.node_ids]
        distance = mean_node_distance(current, self.goal)
        obs = np.concatenate([tip, velocity, current.ravel(), self.goal.ravel()])
        obs = np.clip(obs, self.observation_space.low, self.observation_space.high,
                      dtype=np.float32)
        return obs, distance

    def _info(self, distance: float, unstable: bool) -> dict[str, Any]:
        return {
            "distance": float(distance),
            "is_success": bool(reached(distance, self.threshold)) and not unstable,
            "tip_position": self.scene.tip_position(),
            "goal_index": self.goal_index,
            "simulation_unstable": unstable,
        }


def mean_node_distance(current: np.ndarray, desired: np.ndarray) -> float:
    """Mean Euclidean distance (m) between node positions P_c and P_d, both (m, 3)."""
    return float(np.mean(np.linalg.norm(np.asarray(current) - np.asarray(desired), axis=-1)))
