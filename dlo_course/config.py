"""Configurations of a training run and their presets; imports neither torch nor PyBullet.

:class:`DDPGConfig` holds the agent's hyperparameters, :class:`TrainConfig` everything else
that defines a run (environment, budget, seed, course options); :data:`PRESETS` names the
starting points of ``dlo-course train --preset``. The command line builds its options, their
choices and the defaults in their help from these dataclasses, and imports this module when it
starts: that is why nothing here may import torch or PyBullet (``tests/test_config.py``).
:mod:`dlo_course.ddpg` and :mod:`dlo_course.trainer` re-export the names, their old homes.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import Any

REDUCE_OPS = ("sum", "mean")
"""How the agents' gradients can be combined (``TrainConfig.reduce``); the paper sums."""


@dataclass
class DDPGConfig:
    """Hyperparameters of DDPG. The defaults are the paper's (Section V-B)."""

    actor_lr: float = 1e-4
    """Adam learning rate of the actor (alpha_A)."""
    critic_lr: float = 1e-3
    """Adam learning rate of the critic (alpha_C). Ten times the actor's: the actor follows
    the critic's gradient, so the critic has to be the better-trained of the two."""
    batch_size: int = 128
    """Transitions per update (N). Learning starts once the buffer holds one batch."""
    buffer_size: int = 50_000
    """Capacity of the replay buffer of each agent."""
    gamma: float = 0.99
    """Discount factor: a reward k steps ahead counts gamma**k (horizon ~ 1/(1-gamma) = 100)."""
    tau: float = 0.01
    """Polyak factor of the soft target update, applied after every update."""
    hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Widths of the hidden layers of the actor and of the critic (3 x 256, ReLU)."""
    final_init: float = 3e-3
    """The output layers start with weights and biases uniform in [-final_init, final_init]
    (Lillicrap et al., whose initialisation the paper follows), so initial actions and
    Q-values are close to 0 and the tanh is not saturated. The hidden layers keep PyTorch's
    default, which is Lillicrap's fan-in uniform initialisation."""
    noise_theta: float = 0.15
    """Ornstein–Uhlenbeck mean-reversion rate (the authors' code)."""
    noise_sigma: float = 0.3
    """Ornstein–Uhlenbeck noise scale, in units of the normalised action [-1, 1]."""
    noise_mu: float = 0.0
    """Ornstein–Uhlenbeck mean."""

    # --- course options, off by default (the paper has neither); see docs/design.md ---
    normalize_obs: bool = False
    """Feed the networks ``(obs - offset) / scale`` with a fixed offset and scale from the
    environment (:meth:`DLOShapeEnv.observation_reference`) instead of the raw observation.
    The raw rod observation mixes positions of ~1 m with tip speeds up to 20 m/s."""
    preactivation_l2: float = 0.0
    """Weight of a penalty ``mean(u**2)`` on the actor's output before the tanh, added to the
    policy loss. A saturated tanh has no gradient, so an actor pushed to +-1 stays there;
    the penalty pulls it back where the critic's gradient can reach it."""

    # --- TD3's fixes (Fujimoto et al. 2018), course options, off by default ---
    twin_critics: bool = False
    """Clipped double Q: train a second critic on the same target and build the target from
    the smaller of the two target critics' values. ``critic.pt`` stays the first critic."""
    policy_delay: int = 1
    """Update the actor and all targets once every this many critic updates (1: every time,
    as in DDPG; TD3: 2)."""
    target_noise: float = 0.0
    """Standard deviation of the Gaussian noise added to the target actor's action in the
    Bellman target, in units of the normalised action [-1, 1] (0: none, as in DDPG; TD3:
    0.2)."""
    target_noise_clip: float = 0.5
    """That noise is clipped to [-target_noise_clip, target_noise_clip] (normalised action
    units; TD3: 0.5). Only used when ``target_noise`` > 0."""

    def __post_init__(self) -> None:
        self.hidden_sizes = tuple(int(h) for h in self.hidden_sizes)  # a list from JSON
        if self.batch_size < 1 or self.buffer_size < 1:
            raise ValueError("batch_size and buffer_size must be positive")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"tau must be in (0, 1], got {self.tau}")
        if self.actor_lr <= 0 or self.critic_lr <= 0:
            raise ValueError("learning rates must be positive")
        if self.preactivation_l2 < 0:
            raise ValueError(f"preactivation_l2 must be >= 0, got {self.preactivation_l2}")
        if self.policy_delay < 1:
            raise ValueError(f"policy_delay must be at least 1, got {self.policy_delay}")
        if self.target_noise < 0 or not self.target_noise_clip > 0:
            raise ValueError(f"target_noise must be >= 0 and target_noise_clip > 0, got "
                             f"{self.target_noise} and {self.target_noise_clip}")


@dataclass
class TrainConfig:
    """Everything that defines a training run. Defaults follow the paper, for 2 rod nodes."""

    env_id: str = "DLOShape-v0"
    """Gymnasium id of the environment; any continuous-control (Box) environment works."""
    env_kwargs: dict[str, Any] = field(default_factory=lambda: {"n_nodes": 2})
    """Keyword arguments of ``gymnasium.make`` (for the rod: ``n_nodes`` = 2, 4 or 6)."""
    episodes: int = 63
    """Episodes per agent (the paper: 63, i.e. 32 x 63 = 2016 episodes in all)."""
    steps_per_episode: int = 300
    """Maximum actions per episode; also the environment's ``TimeLimit``
    (``gymnasium.make(..., max_episode_steps=...)``)."""
    seed: int = 0
    """Run seed; each agent's seed is derived from it and its rank
    (:func:`dlo_course.mpi.rank_seed`)."""
    out_dir: str = "runs/train"
    """The run directory (its files: :mod:`dlo_course.rundir`)."""
    checkpoint_every: int = 10
    """Save the resume state every this many episodes (and after the last one); the name
    predates the word, and ``config.json`` files hold it."""
    reduce: str = "sum"
    """How gradients are combined over agents: ``"sum"`` (the paper) or ``"mean"``."""
    warmup: int | None = None
    """Updates start once every agent's buffer holds this many transitions
    (``None``: one batch, as in the paper and the authors' code)."""
    expected_agents: int | None = None
    """Number of MPI ranks the preset is meant for; a different number only gives a warning."""
    updates_per_step: int = 1
    """DDPG updates per environment step (the paper and the authors' code: 1). More reuse
    each costly simulator transition; an update costs a few ms, a rod step ~110 ms."""
    her_k: int = 0
    """Hindsight relabelling (HER, "future" strategy; :mod:`dlo_course.her`): at the end of
    each episode, store every transition again this many times, each time with a goal the
    rod reached later in that episode (0: off, as in the paper; the HER paper: 4). Needs a
    goal-reaching environment such as ``DLOShape-v0``. A trainer option rather than a DDPG
    one: it changes what is stored, and only the trainer knows episodes and the environment's
    observation layout and threshold; the DDPG update never sees the difference."""
    reset_between_episodes: bool = True
    """True: rebuild the world before every training episode (the paper's text). False: a
    training episode starts from the shape the previous one ended in and only a new goal is
    drawn (the authors' code). The first episode, and any after a simulation blow-up, start
    from a rebuilt world anyway. False needs ``DLOShape-v0``, whose reset can keep the shape."""
    validate_every: int = 0
    """Every this many episodes, run the deterministic actor on ``validation_goals`` held-out
    goals (:func:`validate`) and keep the best actor in ``best_actor.pt`` (0: never, as in
    the paper). Costs about 6 s per goal (a rebuilt world and up to ``validation_steps``
    actions), shared by the ranks."""
    validation_goals: int = 30
    """How many validation goals: drawn once from the run's seed among the training goals
    that are not the paper's test goals (:func:`validation_indices`)."""
    validation_steps: int = 30
    """At most this many actions per validation episode (Table I's 30)."""
    torch_threads: int = 1
    """PyTorch threads per process. One: the ranks already fill the cores, and more threads
    per rank would fight over them."""
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    """DDPG hyperparameters (networks, learning rates, buffer, noise)."""

    def __post_init__(self) -> None:
        if isinstance(self.ddpg, dict):  # read back from config.json
            self.ddpg = DDPGConfig(**self.ddpg)
        self.env_kwargs = dict(self.env_kwargs)
        if self.episodes < 1:
            raise ValueError(f"episodes must be at least 1, got {self.episodes}")
        if self.steps_per_episode < 1:
            raise ValueError(f"steps_per_episode must be at least 1, got {self.steps_per_episode}")
        if self.checkpoint_every < 1:
            raise ValueError(f"checkpoint_every must be at least 1, got {self.checkpoint_every}")
        if self.reduce not in REDUCE_OPS:
            raise ValueError(f"reduce must be one of {REDUCE_OPS}, got {self.reduce!r}")
        if self.updates_per_step < 1:
            raise ValueError(f"updates_per_step must be at least 1, got {self.updates_per_step}")
        if self.her_k < 0:
            raise ValueError(f"her_k must be >= 0 (0: no hindsight relabelling), got {self.her_k}")
        if self.validate_every < 0:
            raise ValueError(f"validate_every must be >= 0 (0: no validation), "
                             f"got {self.validate_every}")
        if self.validation_goals < 1 or self.validation_steps < 1:
            raise ValueError("validation_goals and validation_steps must be at least 1, got "
                             f"{self.validation_goals} and {self.validation_steps}")
        if self.warmup is not None and self.warmup < 1:
            raise ValueError(f"warmup must be at least 1, got {self.warmup}")
        if "max_episode_steps" in self.env_kwargs:
            raise ValueError("set steps_per_episode, not env_kwargs['max_episode_steps']")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainConfig":
        return cls(**d)


@dataclass(frozen=True)
class Preset:
    """A named starting configuration, with one line for ``dlo-course train --help``."""

    summary: str
    """What it is for and what it costs, in a few words."""
    config: TrainConfig


_PRESETS = {
    # Seconds of learning code on top of ~40 simulator steps per agent: for CI and notebooks.
    # The batch is small so that updates do happen within 2 x 20 steps.
    "smoke": Preset("seconds, for CI and notebooks",
                    TrainConfig(episodes=2, steps_per_episode=20, checkpoint_every=1,
                                out_dir="runs/smoke", ddpg=DDPGConfig(batch_size=16))),
    # At ~5 simulator actions per second per core: 60 x 150 actions per agent.
    "laptop": Preset("about an hour on a 4-core laptop",
                     TrainConfig(episodes=60, steps_per_episode=150, checkpoint_every=5,
                                 out_dir="runs/laptop", expected_agents=4)),
    "paper": Preset("the paper: 32 agents x 63 episodes x 300 steps, gradients summed",
                    TrainConfig(episodes=63, steps_per_episode=300, checkpoint_every=7,
                                out_dir="runs/paper", expected_agents=32, reduce="sum")),
    # The paper's DDPG with four course options that make a small budget go further
    # (docs/design.md, "Training on two cores"): fixed input scaling, a penalty on the
    # saturated actor, shorter episodes (more goals per transition; test episodes are 30
    # steps) and 2 updates per step. At most 2 x 240 x 60 = 28 800 rod transitions, at ~16
    # transitions/s on 2 cores: up to half an hour of simulation plus the updates.
    "course": Preset("under an hour on 2 cores, with the course options that trained the "
                     "first round's agents",
                     TrainConfig(episodes=240, steps_per_episode=60, checkpoint_every=10,
                                 out_dir="runs/course", expected_agents=2, updates_per_step=2,
                                 ddpg=DDPGConfig(normalize_obs=True, preactivation_l2=0.01,
                                                 noise_sigma=0.15))),
    # A first guess to be tuned by the ablation of issue 12: the course preset's options on
    # the 4-node task, plus every training lever at once (docs/design.md, "Training
    # levers"): hindsight relabelling, TD3's three fixes, episodes that keep the rod's shape
    # (the authors' code), bigger batches and buffer, validation every 20 episodes. At most
    # 30 000 rod transitions per agent: at ~16 transitions/s on 2 cores, about an hour of
    # simulation plus the updates (the shipped agents took 21-46 minutes: episodes end early
    # once the agent reaches its goals).
    "recipe": Preset("provisional: 4 nodes, 2 cores, every training lever on; trained the "
                     "shipped agents",
                     TrainConfig(env_kwargs={"n_nodes": 4}, episodes=500, steps_per_episode=60,
                                 checkpoint_every=10, out_dir="runs/recipe",
                                 expected_agents=2, updates_per_step=2, her_k=4,
                                 reset_between_episodes=False, validate_every=20,
                                 validation_goals=30,
                                 ddpg=DDPGConfig(normalize_obs=True, preactivation_l2=0.01,
                                                 noise_sigma=0.15, batch_size=256,
                                                 buffer_size=200_000, twin_critics=True,
                                                 policy_delay=2, target_noise=0.1,
                                                 target_noise_clip=0.3))),
}

PRESETS: dict[str, TrainConfig] = {name: p.config for name, p in _PRESETS.items()}
"""The trainer's presets by name: smoke, laptop, paper, course, recipe."""
PRESET_SUMMARIES: dict[str, str] = {name: p.summary for name, p in _PRESETS.items()}
"""One line per preset, for the command line's help."""


def preset(name: str, **overrides: Any) -> TrainConfig:
    """A copy of preset ``name`` (a key of :data:`PRESETS`) with some fields changed."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return dataclasses.replace(copy.deepcopy(PRESETS[name]), **overrides)


def paper_default(config_class: type, name: str) -> Any:
    """The default of field ``name`` of a configuration dataclass (the paper's value, for
    :class:`DDPGConfig` and :class:`TrainConfig`); for help texts that must not restate it."""
    for f in dataclasses.fields(config_class):
        if f.name == name:
            if f.default is not dataclasses.MISSING:
                return f.default
            return f.default_factory()  # type: ignore[misc]
    raise AttributeError(f"{config_class.__name__} has no field {name!r}")
