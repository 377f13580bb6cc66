"""Configurations of a training run and their presets; imports neither torch nor PyBullet.

:class:`DDPGConfig` holds the agent's hyperparameters, :class:`TrainConfig` everything else
that defines a run (environment, budget, seed, course options); :data:`PRESETS` names the
starting points of ``dlo-course train --preset``. The command line builds its options, their
choices and the defaults in their help from these dataclasses, and imports this module when it
starts: that is why nothing here may import torch or PyBullet (``tests/test_config.py``).
"""

from __future__ import annotations

import ast
import copy
import dataclasses
import difflib
import functools
import inspect
import textwrap
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dlo_course.task import DEFAULT_N_NODES, NODE_COUNTS, TABLE_THRESHOLDS

REDUCE_OPS = ("sum", "mean")
"""How the agents' gradients can be combined (``TrainConfig.reduce``); the paper sums."""


def bounded(default: Any, low: float | None = None, high: float | None = None, *,
            low_open: bool = False) -> Any:
    """A numeric dataclass field that must lie in [low, high] ((low, high] with
    ``low_open``; ``None``: no bound). The command line's ranges come from here, and
    :func:`check_bounds` checks the value, so the range is written once."""
    return field(default=default, metadata={"range": (low, high, low_open)})


def check_bounds(config: Any) -> None:
    """Raise ``ValueError`` for a field outside its :func:`bounded` range or its choices.

    The dataclasses call it after their own checks, whose messages say more; it catches
    the fields those do not cover."""
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if value is None:
            continue
        if "choices" in f.metadata and value not in f.metadata["choices"]:
            raise ValueError(f"{f.name} must be one of {f.metadata['choices']}, got {value!r}")
        if "range" in f.metadata:
            low, high, low_open = f.metadata["range"]
            if (low is not None and (value <= low if low_open else value < low)) or \
                    (high is not None and value > high):
                raise ValueError(f"{f.name} must be in {describe_range(f.metadata['range'])}, "
                                 f"got {value!r}")


def describe_range(bounds: tuple[float | None, float | None, bool]) -> str:
    """"[1, inf)", "(0, 1]": a :func:`bounded` range for messages."""
    low, high, low_open = bounds
    return (f"{'(' if low_open or low is None else '['}{'-inf' if low is None else low}, "
            f"{'inf)' if high is None else f'{high}]'}")


@dataclass
class DDPGConfig:
    """Hyperparameters of DDPG. The defaults are the paper's (Section V-B)."""

    actor_lr: float = bounded(1e-4, 0.0, low_open=True)
    """Adam learning rate of the actor (alpha_A)."""
    critic_lr: float = bounded(1e-3, 0.0, low_open=True)
    """Adam learning rate of the critic (alpha_C). Ten times the actor's: the actor follows
    the critic's gradient, so the critic has to be the better-trained of the two."""
    batch_size: int = bounded(128, 1)
    """Transitions per update (N). Learning starts once the buffer holds one batch."""
    buffer_size: int = bounded(50_000, 1)
    """Capacity of the replay buffer of each agent."""
    gamma: float = bounded(0.99, 0.0, 1.0)
    """Discount factor: a reward k steps ahead counts gamma**k (horizon ~ 1/(1-gamma) = 100)."""
    tau: float = bounded(0.01, 0.0, 1.0, low_open=True)
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
    preactivation_l2: float = bounded(0.0, 0.0)
    """Weight of a penalty ``mean(u**2)`` on the actor's output before the tanh, added to the
    policy loss. A saturated tanh has no gradient, so an actor pushed to +-1 stays there;
    the penalty pulls it back where the critic's gradient can reach it."""

    # --- TD3's fixes (Fujimoto et al. 2018), course options, off by default ---
    twin_critics: bool = False
    """Clipped double Q: train a second critic on the same target and build the target from
    the smaller of the two target critics' values. ``critic.pt`` stays the first critic."""
    policy_delay: int = bounded(1, 1)
    """Update the actor and all targets once every this many critic updates (1: every time,
    as in DDPG; TD3: 2)."""
    target_noise: float = bounded(0.0, 0.0)
    """Standard deviation of the Gaussian noise added to the target actor's action in the
    Bellman target, in units of the normalised action [-1, 1] (0: none, as in DDPG; TD3:
    0.2)."""
    target_noise_clip: float = bounded(0.5, 0.0, low_open=True)
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
        check_bounds(self)


@dataclass
class TrainConfig:
    """Everything that defines a training run. Defaults follow the paper, for the library's
    default node count (:data:`dlo_course.task.DEFAULT_N_NODES`); the presets name theirs."""

    env_id: str = "DLOShape-v0"
    """Gymnasium id of the environment; any continuous-control (Box) environment works."""
    env_kwargs: dict[str, Any] = field(default_factory=lambda: {"n_nodes": DEFAULT_N_NODES})
    """Keyword arguments of ``gymnasium.make`` (for the rod: ``n_nodes`` = 2, 4 or 6)."""
    episodes: int = bounded(63, 1)
    """Episodes per agent (the paper: 63, i.e. 32 x 63 = 2016 episodes in all)."""
    steps_per_episode: int = bounded(300, 1)
    """Maximum actions per episode; also the environment's ``TimeLimit``
    (``gymnasium.make(..., max_episode_steps=...)``)."""
    seed: int = 0
    """Run seed; each agent's seed is derived from it and its rank
    (:func:`dlo_course.mpi.rank_seed`)."""
    out_dir: str = "runs/train"
    """The run directory (its files: :mod:`dlo_course.rundir`)."""
    checkpoint_every: int = bounded(10, 1)
    """Save the resume state every this many episodes (and after the last one); the name
    predates the word, and ``config.json`` files hold it."""
    reduce: str = field(default="sum", metadata={"choices": REDUCE_OPS})
    """How gradients are combined over agents: ``"sum"`` (the paper) or ``"mean"``."""
    warmup: int | None = bounded(None, 1)
    """Updates start once every agent's buffer holds this many transitions
    (``None``: one batch, as in the paper and the authors' code)."""
    expected_agents: int | None = bounded(None, 1)
    """Number of MPI ranks the preset is meant for; a different number only gives a warning."""
    updates_per_step: int = bounded(1, 1)
    """DDPG updates per environment step (the paper and the authors' code: 1). More reuse
    each costly simulator transition; an update costs a few ms, a rod step ~110 ms."""
    her_k: int = bounded(0, 0)
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
    stop_at_goal: bool = False
    """True: a training episode ends as soon as the goal is reached (the course's first
    recipes). False: every episode runs all ``steps_per_episode`` actions, and reaching the
    goal only stops the Bellman bootstrap (done = 1 in the buffer): the paper ("each agent
    makes 300 actions") and the authors' code. Running on fills the buffer with what happens
    *after* the goal is reached: states close to the goal, where precision is learned.
    A ``config.json`` written before this option existed reads as True, its trainer's
    behaviour."""
    validate_every: int = bounded(0, 0)
    """Every this many episodes, run the deterministic actor on ``validation_goals`` held-out
    goals (:func:`validate`) and keep the best actor in ``best_actor.pt`` (0: never, as in
    the paper). Costs about 6 s per goal (a rebuilt world and up to ``validation_steps``
    actions), shared by the ranks."""
    validation_goals: int = bounded(30, 1)
    """How many validation goals: drawn once from the run's seed among the training goals
    that are not the paper's test goals (:func:`validation_indices`)."""
    validation_steps: int = bounded(30, 1)
    """At most this many actions per validation episode (Table I's 30)."""
    torch_threads: int = bounded(1, 1)
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
        check_bounds(self)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainConfig":
        d = dict(d)
        # Runs recorded before stop_at_goal existed ended their episodes at the goal.
        d.setdefault("stop_at_goal", True)
        return cls(**d)


@dataclass(frozen=True)
class Preset:
    """A named starting configuration, with one line for ``dlo-course train --help``."""

    summary: str
    """What it is for and what it costs, in a few words."""
    config: TrainConfig


def _first_agent() -> dict[str, Any]:
    """The env_kwargs of the presets that train the paper's first agent: the fewest nodes."""
    return {"n_nodes": NODE_COUNTS[0]}


_PRESETS = {
    # Seconds of learning code on top of ~40 simulator steps per agent: for CI and notebooks.
    # The batch is small so that updates do happen within 2 x 20 steps.
    "smoke": Preset("seconds, for CI and notebooks",
                    TrainConfig(env_kwargs=_first_agent(), episodes=2, steps_per_episode=20,
                                checkpoint_every=1,
                                out_dir="runs/smoke", ddpg=DDPGConfig(batch_size=16))),
    # At ~5 simulator actions per second per core: 60 x 150 actions per agent.
    "laptop": Preset("about an hour on a 4-core laptop",
                     TrainConfig(env_kwargs=_first_agent(), episodes=60, steps_per_episode=150,
                                 checkpoint_every=5,
                                 out_dir="runs/laptop", expected_agents=4)),
    "paper": Preset("the paper: 32 agents x 63 episodes x 300 steps, gradients summed",
                    TrainConfig(env_kwargs=_first_agent(), episodes=63, steps_per_episode=300,
                                checkpoint_every=7,
                                out_dir="runs/paper", expected_agents=32, reduce="sum")),
    # The paper's DDPG with four course options that make a small budget go further
    # (docs/design.md, "Training on two cores"): fixed input scaling, a penalty on the
    # saturated actor, shorter episodes (more goals per transition; test episodes are 30
    # steps) and 2 updates per step. At most 2 x 240 x 60 = 28 800 rod transitions, at ~16
    # transitions/s on 2 cores: up to half an hour of simulation plus the updates.
    "course": Preset("under an hour on 2 cores, with the course options that trained the "
                     "first round's agents",
                     TrainConfig(env_kwargs=_first_agent(), episodes=240, steps_per_episode=60,
                                 checkpoint_every=10,
                                 out_dir="runs/course", expected_agents=2, updates_per_step=2,
                                 stop_at_goal=True,
                                 ddpg=DDPGConfig(normalize_obs=True, preactivation_l2=0.01,
                                                 noise_sigma=0.15))),
    # The course preset's options on the 4-node task, plus every training lever at once
    # (docs/design.md, "Training levers"): hindsight relabelling, TD3's three fixes,
    # episodes that keep the rod's shape and run on past the goal (the authors' code),
    # training at 0.03 m instead of 0.05 m, bigger batches and buffer, validation every 20
    # episodes. The shipped 2- and 4-node agents: 500 and 260 episodes on 2 ranks (60 000 and
    # 31 200 transitions, --nodes 2 for the first); the 6-node one was trained before the last
    # two levers (stop_at_goal=True, 0.05 m).
    "recipe": Preset("4 nodes, 2 cores, every training lever on; trained the shipped "
                     "2- and 4-node agents",
                     TrainConfig(env_kwargs={"n_nodes": 4, "threshold": min(TABLE_THRESHOLDS)},
                                 episodes=500,
                                 steps_per_episode=60,
                                 checkpoint_every=10, out_dir="runs/recipe",
                                 expected_agents=2, updates_per_step=2, her_k=4,
                                 reset_between_episodes=False, stop_at_goal=False,
                                 validate_every=20,
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


# --- the fields, their documentation, and settings from a file or the command line ---


def config_fields(config_class: type) -> list[dataclasses.Field]:
    """The settable fields of :class:`TrainConfig` or :class:`DDPGConfig`, in order
    (``TrainConfig.ddpg`` is not one: its own fields are)."""
    return [f for f in dataclasses.fields(config_class) if f.name != "ddpg"]


@functools.lru_cache(maxsize=None)
def field_docs(config_class: type) -> dict[str, str]:
    """Each field's docstring (the string literal under it in the class body), whitespace
    cleaned; the command line's help is taken from these, so each is written once.

    Empty if the source is not available (a byte-code-only install)."""
    try:
        source = textwrap.dedent(inspect.getsource(config_class))
    except (OSError, TypeError):
        return {}
    body = ast.parse(source).body[0].body  # type: ignore[attr-defined]
    docs = {}
    for statement, following in zip(body, body[1:]):
        if (isinstance(statement, ast.AnnAssign) and isinstance(statement.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)):
            docs[statement.target.id] = inspect.cleandoc(following.value.value)
    return docs


def field_types(config_class: type) -> dict[str, Any]:
    """The type of each field, evaluated (the annotations are strings in this module)."""
    return typing.get_type_hints(config_class)


def _type_name(kind: Any) -> str:
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        return " or ".join(_type_name(k) for k in typing.get_args(kind))
    if kind is type(None):
        return "none"
    if typing.get_origin(kind) is tuple:
        return "a list of integers"
    if typing.get_origin(kind) is dict:
        return "a table"
    return {bool: "true or false", int: "an integer", float: "a number",
            str: "a string"}.get(kind, str(kind))


def _coerce(value: Any, kind: Any) -> Any:
    """``value`` as field type ``kind``; ``TypeError`` if it is not one. TOML and JSON have
    no tuples and write 1e-3 and 1 alike, so lists become tuples and integers floats."""
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        if value is None and type(None) in typing.get_args(kind):
            return None
        for option in typing.get_args(kind):
            if option is not type(None):
                try:
                    return _coerce(value, option)
                except TypeError:
                    pass
        raise TypeError
    if typing.get_origin(kind) is tuple:
        if isinstance(value, (list, tuple)) and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value):
            return tuple(value)
        raise TypeError
    if typing.get_origin(kind) is dict:
        if isinstance(value, Mapping) and all(isinstance(k, str) for k in value):
            return dict(value)
        raise TypeError
    if kind is float and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if kind is int and isinstance(value, int) and not isinstance(value, bool):
        return value
    if kind in (bool, str) and isinstance(value, kind):
        return value
    raise TypeError


def _checked(config_class: type, settings: Mapping[str, Any], source: str,
             section: str = "") -> dict[str, Any]:
    """``settings`` checked against ``config_class``'s fields: known names, right types."""
    kinds = field_types(config_class)
    names = [f.name for f in config_fields(config_class)]
    checked = {}
    for name, value in settings.items():
        where = f"{section}{name}"
        if name not in names:
            close = difflib.get_close_matches(name, names, n=1)
            hint = f"; did you mean {section + close[0]!r}?" if close else \
                f"; known: {', '.join(names)}"
            raise ValueError(f"{source}: unknown setting {where!r}{hint}")
        try:
            checked[name] = _coerce(value, kinds[name])
        except TypeError:
            raise ValueError(f"{source}: {where} must be {_type_name(kinds[name])}, "
                             f"got {value!r}") from None
    return checked


def apply_settings(config: TrainConfig, settings: Mapping[str, Any], source: str
                   ) -> TrainConfig:
    """A copy of ``config`` with ``settings`` applied: a mapping laid out as ``config.json``
    (:class:`TrainConfig`'s fields, and ``ddpg``, a mapping of :class:`DDPGConfig`'s).

    ``env_kwargs`` is merged into the configuration's, except that another ``env_id``
    drops them first: the rod's ``n_nodes`` means nothing to another environment.

    Raises:
        ValueError: an unknown name, a value of the wrong type or outside its range; the
            message starts with ``source`` (a file name, "the command line").
    """
    settings = dict(settings)
    ddpg_settings = settings.pop("ddpg", {})
    if not isinstance(ddpg_settings, Mapping):
        raise ValueError(f"{source}: ddpg must be a table of DDPG settings, "
                         f"got {ddpg_settings!r}")
    values = _checked(TrainConfig, settings, source)
    ddpg_values = _checked(DDPGConfig, ddpg_settings, source, section="ddpg.")
    env_kwargs = dict(config.env_kwargs)
    if values.get("env_id", config.env_id) != config.env_id:
        env_kwargs = {}
    env_kwargs.update(values.pop("env_kwargs", {}))
    try:
        ddpg = dataclasses.replace(config.ddpg, **ddpg_values)
        return dataclasses.replace(config, env_kwargs=env_kwargs, ddpg=ddpg, **values)
    except ValueError as err:
        raise ValueError(f"{source}: {err}") from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """A TOML file as a dict (:mod:`tomllib`, or the ``tomli`` package before Python 3.11).

    Raises ``ValueError`` with the file's name if it cannot be read or is not TOML."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        try:
            import tomli as tomllib  # type: ignore[no-redef]
        except ModuleNotFoundError:
            raise ValueError("reading a TOML file needs Python 3.11 or later, or the tomli "
                             "package (pip install tomli)") from None
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as err:
        raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path} is not a valid TOML file: {err}") from None


def experiment_config(preset_name: str | None = None,
                      file_settings: Mapping[str, Any] | None = None,
                      flag_settings: Mapping[str, Any] | None = None,
                      file_label: str = "the configuration file",
                      ) -> tuple[str, TrainConfig, set[str]]:
    """The configuration of an experiment from its three layers: a preset, overridden by a
    file's settings, overridden by the command line's (both laid out as for
    :func:`apply_settings`). A file may name its preset (``preset = "recipe"``); a
    ``preset_name`` given here wins; without either it is "smoke".

    Returns:
        (the preset's name, the configuration, the names of the top-level settings that
        the file or the command line gave).
    """
    file_settings = dict(file_settings or {})
    file_preset = file_settings.pop("preset", None)
    if file_preset is not None and file_preset not in PRESETS:
        raise ValueError(f"{file_label}: unknown preset {file_preset!r}; choose one of "
                         f"{', '.join(PRESETS)}")
    name = preset_name or file_preset or "smoke"
    config = preset(name)
    config = apply_settings(config, file_settings, file_label)
    config = apply_settings(config, flag_settings or {}, "the command line")
    return name, config, set(file_settings) | set(flag_settings or {})


def preset_table() -> str:
    """One line per preset: its name and its one-line summary."""
    width = max(map(len, PRESETS))
    return "\n".join(f"{name:<{width}}  {summary}" for name, summary in PRESET_SUMMARIES.items())
