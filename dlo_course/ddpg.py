"""Deep Deterministic Policy Gradient (DDPG), as used in Section IV of the paper.

Four networks take part (Fig. 2 of the paper):

* the **actor** mu(s): state -> action, the policy the robot follows;
* the **critic** Q(s, a): how much future reward taking action a in state s is worth;
* their **targets** mu'(s) and Q'(s, a): slowly moving copies used to compute the learning
  target of the critic, which keeps that target from chasing itself.

One update (:meth:`DDPG.update`) on a batch of transitions (s, a, r, s', d) does:

1. Bellman target (eq. 1):      Q_B = r + gamma * Q'(s', mu'(s')) * (1 - d)
2. critic step on               critic loss = MSE(Q(s, a), Q_B)
3. actor step on                policy loss = -mean Q(s, mu(s))
4. Polyak averaging (soft update) of both targets:   W_T <- tau * W + (1 - tau) * W_T

Steps 1-4 are written as small pure functions (:func:`bellman_target`, :func:`critic_loss`,
:func:`policy_loss`, :func:`polyak_update`) that the lessons ask you to write yourself.

Three fixes of TD3 (Fujimoto et al. 2018, "Addressing Function Approximation Error in
Actor-Critic Methods") are course options, off by default (the paper has none of them):

* ``twin_critics`` (clipped double Q): two critics learn the same target, and the target uses
  the smaller of their two target values, ``min(Q'_1, Q'_2)``, which counters the critic's
  tendency to overestimate the actions the actor picks;
* ``policy_delay``: the actor and the targets are updated once every d critic updates, so the
  actor follows a critic that has had time to settle;
* ``target_noise`` / ``target_noise_clip`` (target policy smoothing): the target action is
  ``mu'(s')`` plus clipped Gaussian noise (:func:`smoothed_target_action`), so the target is
  an average over nearby actions and a narrow peak of Q' cannot be exploited.

Shapes: ``B`` is the batch size, ``obs_dim`` the observation length (18/30/42 for 2/4/6 rod
nodes), ``act_dim`` the action length (3). Every Q-value tensor has shape (B, 1), and so do
rewards and done flags once inside :meth:`DDPG.update`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch
from torch import nn

from dlo_course.config import DDPGConfig


# --- the pieces of one update, as pure functions ---


def bellman_target(reward: torch.Tensor, next_q: torch.Tensor, done: torch.Tensor,
                   gamma: float) -> torch.Tensor:
    """Eq. (1) of the paper: Q_B = r + gamma * Q'(s', mu'(s')) * (1 - d).

    Args:
        reward: (B, 1) rewards r.
        next_q: (B, 1) target critic's value of the next state under the target actor.
        done: (B, 1) 1.0 where s' is terminal: nothing follows it, so no bootstrapping.
        gamma: discount factor.

    Returns:
        (B, 1) the critic's regression target. Call it under ``torch.no_grad()``: the target
        is a fixed label, not something to differentiate through.
    """
    return reward + gamma * next_q * (1.0 - done)


def critic_loss(q: torch.Tensor, q_target: torch.Tensor) -> torch.Tensor:
    """Mean squared error between the critic's Q(s, a) and the Bellman target Q_B.

    Args:
        q: (B, 1) the critic's estimates.
        q_target: (B, 1) Bellman targets, same shape.

    Returns:
        A scalar tensor.
    """
    if q.shape != q_target.shape:
        # The classic silent DDPG bug: (B, 1) - (B,) broadcasts to (B, B), and the loss then
        # compares every Q with every target. Refuse instead of learning nonsense.
        raise ValueError(f"q {tuple(q.shape)} and q_target {tuple(q_target.shape)} "
                         "must have the same shape")
    return ((q - q_target) ** 2).mean()


def policy_loss(q: torch.Tensor) -> torch.Tensor:
    """Policy (actor) loss: -mean Q(s, mu(s)). Minimising it climbs the critic's estimate.

    Args:
        q: (B, 1) the critic's values of the actor's own actions, Q(s, mu(s)).

    Returns:
        A scalar tensor.
    """
    return -q.mean()


def preactivation_penalty(u: torch.Tensor, weight: float) -> torch.Tensor:
    """``weight * mean(u**2)``: the optional course penalty on the actor's pre-tanh output.

    Args:
        u: (B, act_dim) the actor's output before the tanh (:meth:`Actor.preactivation`).
        weight: ``DDPGConfig.preactivation_l2`` (0 in the paper).

    Returns:
        A scalar tensor.
    """
    return weight * (u ** 2).mean()


def smoothed_target_action(action: torch.Tensor, noise: torch.Tensor, noise_clip: float,
                           action_scale: torch.Tensor, action_bias: torch.Tensor
                           ) -> torch.Tensor:
    """TD3's target policy smoothing: a' = clip(mu'(s') + scale * clip(eps, -c, c), low, high).

    Args:
        action: (B, act_dim) the target actor's actions mu'(s'), inside [low, high].
        noise: (B, act_dim) the noise eps, in units of the normalised action [-1, 1].
        noise_clip: c, the largest noise kept (``DDPGConfig.target_noise_clip``).
        action_scale, action_bias: (act_dim,) the actor's scaling of [-1, 1] onto
            [low, high] (:class:`Actor`): low = bias - scale, high = bias + scale.

    Returns:
        (B, act_dim) the smoothed target actions, inside [low, high].
    """
    eps = noise.clamp(-noise_clip, noise_clip)
    return torch.clamp(action + action_scale * eps, action_bias - action_scale,
                       action_bias + action_scale)


@torch.no_grad()
def td3_target(reward: torch.Tensor, next_obs: torch.Tensor, done: torch.Tensor, gamma: float,
               actor_target: nn.Module, critic_targets: Sequence[nn.Module],
               noise: torch.Tensor | None = None, noise_clip: float = 0.5) -> torch.Tensor:
    """The critic's label with TD3's clipped double Q and target policy smoothing, written out
    as one function: what :meth:`DDPG.update` computes (:meth:`DDPG.target_value`, then
    :func:`bellman_target`) when ``twin_critics`` and ``target_noise`` are set (lesson 15).

    y = r + gamma * (1 - d) * min_i Q'_i(s', a'),  a' = smoothed mu'(s') (with ``noise``).

    Args:
        reward, done: (B, 1) rewards and terminal flags.
        next_obs: (B, obs_dim) next observations s'.
        gamma: discount factor.
        actor_target: the target actor mu' (an :class:`Actor`: its ``action_scale`` and
            ``action_bias`` give the action bounds).
        critic_targets: the target critics, one (DDPG) or two (TD3); the smallest value wins.
        noise: (B, act_dim) the smoothing noise eps in units of the normalised action (TD3:
            ``target_noise * N(0, 1)``), or ``None`` for the plain mu'(s').
        noise_clip: c, the largest noise kept (:func:`smoothed_target_action`).

    Returns:
        (B, 1) targets, without gradient.
    """
    next_act = actor_target(next_obs)
    if noise is not None:
        next_act = smoothed_target_action(next_act, noise, noise_clip,
                                          actor_target.action_scale, actor_target.action_bias)
    next_q = critic_targets[0](next_obs, next_act)
    for critic in critic_targets[1:]:
        next_q = torch.min(next_q, critic(next_obs, next_act))
    return bellman_target(reward, next_q, done, gamma)


def actor_update_due(critic_updates: int, policy_delay: int) -> bool:
    """TD3's delayed policy update: does the actor (and do the targets) take a step at this
    update? ``critic_updates`` counts the critic updates so far, this one included (1 at
    the first); with ``policy_delay`` d the actor steps at updates d, 2d, 3d, ... (every
    update when d = 1, the paper's DDPG). :meth:`DDPG.update` decides with it."""
    return critic_updates % policy_delay == 0


@torch.no_grad()
def polyak_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    """Soft update, in place: W_T <- tau * W + (1 - tau) * W_T for every parameter.

    Args:
        target: the target network (actor target or critic target), modified in place.
        source: the network being trained, same architecture.
        tau: Polyak factor; with tau = 0.01 the target moves 1 % of the way each update.
    """
    for w_target, w in zip(target.parameters(), source.parameters(), strict=True):
        w_target.mul_(1.0 - tau).add_(w, alpha=tau)


# --- the networks ---


@dataclass(frozen=True)
class UpdateRules:
    """The four formulas of a DDPG update, as functions the agent calls: the paper's by
    default. Pass others to :class:`DDPG` (or to :func:`dlo_course.trainer.train`) to try a
    variant, or to train with your own implementations, as lesson 04 does; nothing in the
    library is patched, so the next agent gets the paper's formulas again."""

    bellman_target: Callable[..., torch.Tensor] = bellman_target
    """(reward, next_q, done, gamma) -> (B, 1) targets y = r + gamma (1 - done) Q'."""
    critic_loss: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] = critic_loss
    """(q, q_target), both (B, 1) -> scalar loss."""
    policy_loss: Callable[[torch.Tensor], torch.Tensor] = policy_loss
    """(q,) (B, 1) values of the actor's actions -> scalar loss."""
    polyak_update: Callable[[nn.Module, nn.Module, float], None] = polyak_update
    """(target, source, tau): move the target's weights towards the source's, in place."""


def mlp(in_dim: int, hidden_sizes: Sequence[int], out_dim: int, final_init: float) -> nn.Sequential:
    """Fully connected network: Linear-ReLU for each hidden layer, then a Linear output."""
    layers: list[nn.Module] = []
    width = in_dim
    for h in hidden_sizes:
        layers += [nn.Linear(width, h), nn.ReLU()]
        width = h
    out = nn.Linear(width, out_dim)
    nn.init.uniform_(out.weight, -final_init, final_init)
    nn.init.uniform_(out.bias, -final_init, final_init)
    layers.append(out)
    return nn.Sequential(*layers)


class ObservationScaling(nn.Module):
    """``(obs - offset) / scale``, with a fixed offset and scale stored as buffers (saved with
    the network, never trained). Identity when both are ``None``.

    Args:
        obs_dim: observation length.
        offset, scale: (obs_dim,) arrays, or ``None`` for no scaling.
    """

    def __init__(self, obs_dim: int, offset: Any = None, scale: Any = None) -> None:
        super().__init__()
        offset = np.zeros(obs_dim) if offset is None else np.asarray(offset)
        scale = np.ones(obs_dim) if scale is None else np.asarray(scale)
        if offset.shape != (obs_dim,) or scale.shape != (obs_dim,):
            raise ValueError(f"observation offset and scale must have shape ({obs_dim},), "
                             f"got {offset.shape} and {scale.shape}")
        if not (np.all(np.isfinite(offset)) and np.all(np.isfinite(scale)) and np.all(scale > 0)):
            raise ValueError("observation offset must be finite and scale finite and positive")
        self.register_buffer("offset", torch.as_tensor(offset, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (obs - self.offset) / self.scale


def _scaling_kwargs(offset: Any, scale: Any) -> dict[str, Any]:
    # Lists, so that save_network's kwargs load with torch.load(weights_only=True).
    as_list = lambda a: None if a is None else np.asarray(a, dtype=np.float64).tolist()  # noqa: E731
    return {"obs_offset": as_list(offset), "obs_scale": as_list(scale)}


class Actor(nn.Module):
    """The policy mu(s): observation -> action inside the action bounds.

    A tanh squashes the output into [-1, 1] (the paper: the tip velocities stay in [-1, 1]),
    then it is scaled to the environment's bounds [low, high], so the same class also drives
    e.g. Pendulum-v1 whose torque lies in [-2, 2].

    Args:
        obs_dim: observation length.
        act_dim: action length.
        action_low, action_high: (act_dim,) bounds of the action space (or scalars).
        hidden_sizes: widths of the hidden layers.
        final_init: half-width of the uniform initialisation of the output layer.
        obs_offset, obs_scale: (obs_dim,) optional fixed input scaling
            (:class:`ObservationScaling`); ``None``: raw observations, as in the paper.
    """

    def __init__(self, obs_dim: int, act_dim: int, action_low: Any = -1.0,
                 action_high: Any = 1.0, hidden_sizes: Sequence[int] = (256, 256, 256),
                 final_init: float = 3e-3, obs_offset: Any = None, obs_scale: Any = None
                 ) -> None:
        super().__init__()
        low = np.broadcast_to(np.asarray(action_low, dtype=np.float32), (act_dim,))
        high = np.broadcast_to(np.asarray(action_high, dtype=np.float32), (act_dim,))
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high > low)):
            raise ValueError(f"action bounds must be finite with high > low, got {low}, {high}")
        self.init_kwargs = dict(obs_dim=int(obs_dim), act_dim=int(act_dim),
                                action_low=low.tolist(), action_high=high.tolist(),
                                hidden_sizes=list(hidden_sizes), final_init=float(final_init),
                                **_scaling_kwargs(obs_offset, obs_scale))
        self.scaling = ObservationScaling(obs_dim, obs_offset, obs_scale)
        self.net = mlp(obs_dim, hidden_sizes, act_dim, final_init)
        # Buffers, not parameters: saved with the network but never trained.
        self.register_buffer("action_scale", torch.as_tensor((high - low) / 2))
        self.register_buffer("action_bias", torch.as_tensor((high + low) / 2))

    def preactivation(self, obs: torch.Tensor) -> torch.Tensor:
        """obs: (B, obs_dim) -> (B, act_dim) the output before the tanh."""
        return self.net(self.scaling(obs))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """obs: (B, obs_dim) -> actions (B, act_dim) in [low, high]."""
        return self.squash(self.preactivation(obs))

    def squash(self, u: torch.Tensor) -> torch.Tensor:
        """(B, act_dim) pre-tanh outputs -> actions in [low, high]."""
        return self.action_bias + self.action_scale * torch.tanh(u)


class Critic(nn.Module):
    """The action-value function Q(s, a): one scalar per (observation, action) pair.

    The action enters at the input, concatenated with the observation.

    Args:
        obs_dim: observation length.
        act_dim: action length.
        hidden_sizes: widths of the hidden layers.
        final_init: half-width of the uniform initialisation of the output layer.
        obs_offset, obs_scale: (obs_dim,) optional fixed input scaling, as for the actor.
    """

    def __init__(self, obs_dim: int, act_dim: int, hidden_sizes: Sequence[int] = (256, 256, 256),
                 final_init: float = 3e-3, obs_offset: Any = None, obs_scale: Any = None
                 ) -> None:
        super().__init__()
        self.init_kwargs = dict(obs_dim=int(obs_dim), act_dim=int(act_dim),
                                hidden_sizes=list(hidden_sizes), final_init=float(final_init),
                                **_scaling_kwargs(obs_offset, obs_scale))
        self.scaling = ObservationScaling(obs_dim, obs_offset, obs_scale)
        self.net = mlp(obs_dim + act_dim, hidden_sizes, 1, final_init)

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        """obs: (B, obs_dim), act: (B, act_dim) -> Q-values (B, 1)."""
        return self.net(torch.cat([self.scaling(obs), act], dim=-1))


@torch.no_grad()
def policy_action(actor: nn.Module, obs: np.ndarray) -> np.ndarray:
    """The deterministic policy's action for an observation: NumPy in, NumPy out, no
    gradient. Every place that turns an observation into an action goes through here
    (training, validation, evaluation, figures), so they all compute it the same way.

    Args:
        actor: an :class:`Actor`, or any module mapping (B, obs_dim) float32 tensors to
            (B, act_dim) actions (e.g. :func:`dlo_course.evaluation.recorded_tip_controller`).
        obs: (obs_dim,) one observation or (B, obs_dim) several, any float dtype (cast to
            float32, the networks' dtype).

    Returns:
        float32 array of the actor's output, (act_dim,) or (B, act_dim): the same batch
        shape as ``obs``. A single observation is *not* given a batch axis: a network's
        last bits may differ between a vector and a batch of one, and callers keep the
        shape they always used so that seeded results stay bit-identical.
    """
    return actor(torch.as_tensor(np.asarray(obs, dtype=np.float32))).numpy()


def save_network(net: Actor | Critic, path: str | Path) -> None:
    """Save a network with what is needed to rebuild it (see :func:`load_network`)."""
    torch.save({"class": type(net).__name__, "kwargs": net.init_kwargs,
                "state_dict": net.state_dict()}, path)


def load_network(path: str | Path) -> Actor | Critic:
    """Rebuild an :class:`Actor` or :class:`Critic` saved by :func:`save_network`."""
    blob = torch.load(path, map_location="cpu", weights_only=True)
    cls = {"Actor": Actor, "Critic": Critic}[blob["class"]]
    net = cls(**blob["kwargs"])
    net.load_state_dict(blob["state_dict"])
    return net


# --- the agent ---


GradReducer = Callable[[nn.Module], None]


class DDPG:
    """A DDPG agent: actor, critic, their targets and their Adam optimisers.

    With ``config.twin_critics`` (TD3) it also holds ``critic2``, its target and optimiser;
    otherwise those attributes are ``None``.

    Args:
        obs_dim: observation length.
        act_dim: action length.
        action_low, action_high: bounds of the action space (arrays of act_dim, or scalars).
        config: hyperparameters; the paper's by default.
        obs_offset, obs_scale: (obs_dim,) fixed input scaling of both networks, used only
            when ``config.normalize_obs`` is set (e.g. from
            :meth:`DLOShapeEnv.observation_reference`).
        rules: the formulas :meth:`update` uses (:class:`UpdateRules`); the paper's by default.
        critic_class: the critics' class, called as ``critic_class(obs_dim, act_dim,
            hidden_sizes, final_init)`` (plus ``obs_offset=, obs_scale=`` with
            ``normalize_obs``): :class:`Critic` by default; lesson 04 trains with the
            student's (:mod:`dlo_course.pendulum`).
    """

    def __init__(self, obs_dim: int, act_dim: int, action_low: Any = -1.0,
                 action_high: Any = 1.0, config: DDPGConfig | None = None,
                 obs_offset: Any = None, obs_scale: Any = None,
                 rules: UpdateRules | None = None,
                 critic_class: Callable[..., nn.Module] | None = None) -> None:
        self.config = cfg = config or DDPGConfig()
        self.rules = rules or UpdateRules()
        if cfg.normalize_obs and (obs_offset is None or obs_scale is None):
            raise ValueError("normalize_obs needs obs_offset and obs_scale")
        if not cfg.normalize_obs:
            obs_offset = obs_scale = None
        self.actor = Actor(obs_dim, act_dim, action_low, action_high, cfg.hidden_sizes,
                           cfg.final_init, obs_offset, obs_scale)
        critic_class = critic_class or Critic
        # Without normalize_obs the scaling is left out, so a critic class without it fits.
        scaling = (dict(obs_offset=obs_offset, obs_scale=obs_scale) if cfg.normalize_obs
                   else {})
        self.critic = critic_class(obs_dim, act_dim, cfg.hidden_sizes, cfg.final_init,
                                   **scaling)
        # Created after the first critic, so that the actor and the first critic start from
        # the same weights with or without it.
        self.critic2 = (critic_class(obs_dim, act_dim, cfg.hidden_sizes, cfg.final_init,
                                     **scaling) if cfg.twin_critics else None)
        # Targets start as exact copies and are only ever changed by polyak_update.
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.critic2_target = (None if self.critic2 is None
                               else copy.deepcopy(self.critic2).requires_grad_(False))
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=cfg.actor_lr)
        self.critic_optimizer = torch.optim.Adam(self.critic.parameters(), lr=cfg.critic_lr)
        self.critic2_optimizer = (None if self.critic2 is None
                                  else torch.optim.Adam(self.critic2.parameters(),
                                                        lr=cfg.critic_lr))
        self.updates = 0  # critic updates so far; policy_delay counts them

    @property
    def critics(self) -> list[Critic]:
        """The trained critics: ``[critic]``, or ``[critic, critic2]`` with twin critics."""
        return [self.critic] if self.critic2 is None else [self.critic, self.critic2]

    def sync_targets(self) -> None:
        """Make the targets exact copies of the networks again (after they were replaced,
        e.g. by an MPI broadcast)."""
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        if self.critic2 is not None:
            self.critic2_target.load_state_dict(self.critic2.state_dict())

    @torch.no_grad()
    def act(self, obs: np.ndarray, noise: Any = None) -> np.ndarray:
        """The action to send to the environment.

        Args:
            obs: (obs_dim,) one observation (or (B, obs_dim) several).
            noise: exploration noise with a ``sample()`` method returning (act_dim,) values in
                units of the normalised action [-1, 1] (e.g. :class:`~dlo_course.noise.OUNoise`);
                ``None`` for the deterministic policy (evaluation).

        Returns:
            float32 array, (act_dim,) (or (B, act_dim)), clipped to the action bounds.
        """
        action = policy_action(self.actor, obs)
        scale = self.actor.action_scale.numpy()
        if noise is not None:
            # Noise is drawn for the normalised action and scaled like the actor's tanh output,
            # so sigma = 0.3 means the same exploration on any action range.
            action = action + scale * noise.sample()
        low = self.actor.action_bias.numpy() - scale
        high = self.actor.action_bias.numpy() + scale
        return np.clip(action, low, high).astype(np.float32)

    @torch.no_grad()
    def target_value(self, next_obs: torch.Tensor) -> torch.Tensor:
        """Q'(s', a') in the Bellman target, with a' = mu'(s') (DDPG).

        With TD3's options: a' is smoothed (``target_noise``, :func:`smoothed_target_action`)
        and Q' is the smaller of the two target critics (``twin_critics``).

        Args:
            next_obs: (B, obs_dim) next observations s'.

        Returns:
            (B, 1) target values, without gradient.
        """
        cfg = self.config
        next_act = self.actor_target(next_obs)
        if cfg.target_noise > 0:  # TD3: target policy smoothing
            noise = cfg.target_noise * torch.randn_like(next_act)
            next_act = smoothed_target_action(next_act, noise, cfg.target_noise_clip,
                                              self.actor.action_scale, self.actor.action_bias)
        next_q = self.critic_target(next_obs, next_act)
        if self.critic2_target is not None:  # TD3: clipped double Q
            next_q = torch.min(next_q, self.critic2_target(next_obs, next_act))
        return next_q

    def update(self, batch: Mapping[str, Any], grad_reducer: GradReducer | None = None
               ) -> dict[str, float]:
        """One DDPG update: critic step, actor step, soft update of both targets.

        With TD3's options, the second critic takes a step after the first, and the actor
        step and the soft updates happen only on every ``policy_delay``-th update.

        Args:
            batch: arrays or tensors (as from :meth:`ReplayBuffer.sample`): ``obs``
                (B, obs_dim), ``act`` (B, act_dim), ``rew`` (B,), ``next_obs`` (B, obs_dim),
                ``done`` (B,).
            grad_reducer: called with each module after its ``backward()`` and before its
                optimiser step: the critic (then the second critic, if any), then the actor.
                With MPI it sums (or averages) the gradients of all agents, so that every
                agent takes the same step (:func:`dlo_course.mpi.allreduce_gradients`).

        Returns:
            Scalars for logging: ``critic_loss`` (the first critic's), ``q_mean`` (mean
            Q(s, a) of the batch, first critic) and ``policy_loss``, the last only when the
            actor was updated (always, unless ``policy_delay`` > 1).
        """
        cfg = self.config
        obs, act, next_obs = (torch.as_tensor(batch[k], dtype=torch.float32)
                              for k in ("obs", "act", "next_obs"))
        # (B,) -> (B, 1), the shape of the critic's output; see critic_loss for why it matters.
        rew = torch.as_tensor(batch["rew"], dtype=torch.float32).reshape(-1, 1)
        done = torch.as_tensor(batch["done"], dtype=torch.float32).reshape(-1, 1)

        # 1-2. Critic: regress Q(s, a) on the Bellman target built from the target networks.
        with torch.no_grad():
            q_target = self.rules.bellman_target(rew, self.target_value(next_obs), done,
                                                 cfg.gamma)
        q = self.critic(obs, act)
        loss_q = self.rules.critic_loss(q, q_target)
        self._step(self.critic, self.critic_optimizer, loss_q, grad_reducer)
        if self.critic2 is not None:  # TD3: the second critic learns the same target
            loss_q2 = self.rules.critic_loss(self.critic2(obs, act), q_target)
            self._step(self.critic2, self.critic2_optimizer, loss_q2, grad_reducer)
        self.updates += 1
        stats = {"critic_loss": loss_q.item(), "q_mean": q.mean().item()}
        if not actor_update_due(self.updates, cfg.policy_delay):
            return stats  # TD3: the actor and the targets wait for the critics to settle

        # 3. Actor: follow the (just updated) critic uphill. The critic is frozen meanwhile:
        # the policy loss must move the actor only, and this skips its useless gradients.
        self.critic.requires_grad_(False)
        u = self.actor.preactivation(obs)
        loss_pi = self.rules.policy_loss(self.critic(obs, self.actor.squash(u)))
        if cfg.preactivation_l2 > 0:  # course option, not in the paper
            loss_pi = loss_pi + preactivation_penalty(u, cfg.preactivation_l2)
        self._step(self.actor, self.actor_optimizer, loss_pi, grad_reducer)
        self.critic.requires_grad_(True)

        # 4. Targets trail the trained networks.
        self.rules.polyak_update(self.actor_target, self.actor, cfg.tau)
        self.rules.polyak_update(self.critic_target, self.critic, cfg.tau)
        if self.critic2 is not None:
            self.rules.polyak_update(self.critic2_target, self.critic2, cfg.tau)

        stats["policy_loss"] = loss_pi.item()
        return stats

    @staticmethod
    def _step(module: nn.Module, optimizer: torch.optim.Optimizer, loss: torch.Tensor,
              grad_reducer: GradReducer | None) -> None:
        """One gradient step of ``module`` on ``loss``, the gradient combined over agents."""
        optimizer.zero_grad()
        loss.backward()
        if grad_reducer is not None:
            grad_reducer(module)
        optimizer.step()

    def state_dict(self) -> dict[str, Any]:
        """A snapshot of the networks, targets and optimiser states (Adam's moments included),
        plus the second critic's with twin critics, and the update count (``policy_delay``).

        Deep-copied: PyTorch's ``state_dict()`` returns references to live tensors, and an
        optimiser loading them would share its moment estimates with this agent."""
        state = {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "critic_optimizer": self.critic_optimizer.state_dict(),
            "updates": self.updates,
        }
        if self.critic2 is not None:
            state.update(critic2=self.critic2.state_dict(),
                         critic2_target=self.critic2_target.state_dict(),
                         critic2_optimizer=self.critic2_optimizer.state_dict())
        return copy.deepcopy(state)

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        if (self.critic2 is not None) != ("critic2" in state):
            raise ValueError(f"twin critics mismatch: the saved agent has "
                             f"{'two critics' if 'critic2' in state else 'one critic'}, "
                             f"this one {'two' if self.critic2 is not None else 'one'}")
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.critic_optimizer.load_state_dict(state["critic_optimizer"])
        if self.critic2 is not None:
            self.critic2.load_state_dict(state["critic2"])
            self.critic2_target.load_state_dict(state["critic2_target"])
            self.critic2_optimizer.load_state_dict(state["critic2_optimizer"])
        self.updates = int(state.get("updates", 0))  # absent in resume states older than TD3
