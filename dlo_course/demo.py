"""``dlo-course demo``: episodes of the environment, saved as pictures and a video.

The quickest way to see the task. Without a policy: random actions, a goal drawn from a
database. With a trained agent (``--agent``) or a classical controller (``--controller``):
test episodes as Table I runs them, by default on a test goal the shipped 4-node agent
reaches. Every frame shows the rendered robot and rod with P_c (blue) and P_d (red) marked,
and the mean node distance written in its corner.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from tqdm.auto import tqdm

from dlo_course.plots import caption_frame, plot_episode_frames, save_gif, save_mp4
from dlo_course.task import DEFAULT_N_NODES, reached

DEFAULT_AGENT_GOALS = "small-test"
"""Where an agent's or a controller's demo takes its goals: the paper's test goals."""

DEFAULT_GOAL_INDEX = 15
"""The goal an agent's demo shows unless told otherwise: small-test goal 15. The shipped
4-node agent brings the rod from 0.188 m to 0.041 m of it in 8 actions, below the demo's
0.05 m; the shipped 2- and 6-node agents reach it too, to 0.040 m in 7 actions and 0.037 m in
8 (``dlo-course demo --agent data/checkpoints/nodesN``, issue 36)."""

HOLD_SECONDS = 1.5
"""How long the videos show each episode's last frame."""


@dataclass
class Episode:
    """One rendered episode: a frame before the first action and one after each action."""

    who: str
    """What acted, e.g. "agent nodes4" or "random actions"."""
    goals: str
    goal_index: int
    threshold: float
    frames: list[np.ndarray] = field(default_factory=list)
    """(H, W, 3) uint8 renders, as the environment draws them (crosses, no text)."""
    distances: list[float] = field(default_factory=list)
    """Mean node distance (m) in each frame."""
    total_reward: float = 0.0

    @property
    def actions(self) -> int:
        return len(self.frames) - 1

    @property
    def success(self) -> bool:
        return bool(reached(self.distances[-1], self.threshold))

    def captioned_frames(self) -> list[np.ndarray]:
        """The frames with what acted, the goal, the action count and the mean node distance
        written on each (:func:`dlo_course.plots.caption_frame`)."""
        captioned = []
        for step, (frame, distance) in enumerate(zip(self.frames, self.distances)):
            done = f"  (below {self.threshold:g} m: done)" if reached(distance, self.threshold) \
                else ""
            captioned.append(caption_frame(frame, (
                f"{self.who}, goal {self.goal_index} of {self.goals}",
                f"action {step}: mean node distance {distance:.3f} m{done}")))
        return captioned


def render_frame(env, width: int | None = None, height: int | None = None) -> np.ndarray:
    """The environment's picture, at the scene camera's default size or at ``width`` x
    ``height``.

    Gymnasium's ``render()`` takes no arguments, so a size of our own needs the scene's
    renderer, given the same markers as :meth:`dlo_course.env.DLOShapeEnv.render` draws.
    """
    if width is None and height is None:
        return env.render()
    # One side given: the other keeps the camera's 4:3.
    width = width or round(height * 4 / 3)
    height = height or round(width * 3 / 4)
    base = env.unwrapped
    nodes = base.scene.node_positions()
    return base.scene.render(width, height,
                             markers=((nodes[base.node_ids], (40, 80, 255)),
                                      (base.goal, (230, 30, 30))))


def play_rendered(env, act: Callable[[np.ndarray], np.ndarray], obs: np.ndarray, info: dict,
                  episode: Episode, max_steps: int, width: int | None = None,
                  height: int | None = None, bar=None) -> Episode:
    """Run one episode from a reset that returned (``obs``, ``info``), rendering every
    state into ``episode``. Stops below the environment's threshold, at its time limit, or
    after ``max_steps`` actions, as :func:`dlo_course.evaluation.play_episode` does."""
    episode.frames.append(render_frame(env, width, height))
    episode.distances.append(float(info["distance"]))
    for _ in range(max_steps):
        obs, reward, terminated, truncated, info = env.step(act(obs))
        episode.total_reward += float(reward)
        episode.frames.append(render_frame(env, width, height))
        episode.distances.append(float(info["distance"]))
        if bar is not None:
            bar.update(1)
        if terminated or truncated:
            break
    return episode


def _policy(agent, controller: str | None, n_nodes: int | None):
    """(who, n_nodes, start, act) for a trained agent, a named controller or neither.

    ``start(env, obs)`` prepares an episode; ``act(obs)`` gives each action. Returns None for
    neither (random actions, which need the environment's action space)."""
    if agent is not None:
        from dlo_course.ddpg import policy_action
        from dlo_course.evaluation import load_actor

        actor, n_nodes = load_actor(agent, n_nodes)

        def act(obs):
            # A batch of one, exactly as the evaluation does, so that the demo's episode is
            # the very episode Table I scored.
            return policy_action(actor, np.asarray(obs)[None])[0]

        return f"agent {Path(agent).resolve().name}", n_nodes, (lambda env, obs: None), act
    if controller is not None:
        from dlo_course.jacobian import CONTROLLERS

        policy = CONTROLLERS[controller](n_nodes or DEFAULT_N_NODES)

        def start(env, obs):
            policy.bind(env)
            policy.reset(obs)

        return f"{controller} controller", policy.n_nodes, start, policy.act
    return None


def run_demo(n_nodes: int | None = None, goals: str | None = None, steps: int = 30,
             seed: int = 0, out: str | Path = "reports/demo.png", policy=None, *,
             agent: str | Path | None = None, controller: str | None = None,
             goal_indices: Sequence[int] | None = None, episodes: int | None = None,
             width: int | None = None, height: int | None = None, fps: int = 10,
             mp4: bool = True) -> str:
    """Run and render episodes; save ``out`` (the first episode's first | last frame), a
    GIF of every frame beside it, and an MP4 too when ffmpeg is installed.

    Args:
        n_nodes: selected nodes (default 4; an agent's is read from its actor).
        goals: goal source (:func:`dlo_course.database.resolve_goals`); default "small" for
            random actions, :data:`DEFAULT_AGENT_GOALS` for an agent or a controller.
        steps: at most this many actions per episode.
        seed: the random actions and goals; with ``episodes``, the evaluation's goal draw.
        policy: a callable obs -> action, e.g. ``functools.partial(policy_action, actor)``
            (:func:`dlo_course.ddpg.policy_action`); None with neither ``agent`` nor
            ``controller``: uniformly random actions.
        agent: a trained agent (:func:`dlo_course.evaluation.load_actor`).
        controller: a classical controller's name (:data:`dlo_course.jacobian.CONTROLLERS`).
        goal_indices: the goals, one episode each. Default: :data:`DEFAULT_GOAL_INDEX` for an
            agent or a controller, a goal drawn from ``seed`` for random actions.
        episodes: instead of ``goal_indices``, this many episodes on the goals Table I's
            protocol draws with ``seed`` (:func:`dlo_course.evaluation.goal_schedule`).
        width, height: frame size in pixels (default: the scene camera's 480 x 360).
        fps: frames per second of the videos.
        mp4: also write an MP4 when an encoder is installed.

    Returns:
        a summary: one line per episode, then the files written.
    """
    from dlo_course.env import make_env  # imports PyBullet: only when needed
    from dlo_course.evaluation import goal_schedule

    if agent is not None and controller is not None:
        raise ValueError("give an agent or a controller, not both")
    if goal_indices and episodes:
        raise ValueError("give goal indices or a number of episodes, not both")
    chosen = _policy(agent, controller, n_nodes)
    if chosen is not None:
        who, n_nodes, start, act = chosen
        goals = goals or DEFAULT_AGENT_GOALS
    else:
        who, start, act = "random actions" if policy is None else "policy", None, policy
        n_nodes, goals = n_nodes or DEFAULT_N_NODES, goals or "small"

    # No TimeLimit: the loop stops each episode after `steps` itself.
    env = make_env(max_episode_steps=None, n_nodes=n_nodes, goals=goals,
                   render_mode="rgb_array")
    recorded: list[Episode] = []
    try:
        if episodes:
            goal_indices = goal_schedule(len(env.unwrapped.goal_set), episodes, seed).tolist()
        elif not goal_indices and chosen is not None:
            goal_indices = [DEFAULT_GOAL_INDEX]
        # None: one episode on a goal the reset draws from the seed (the random demo).
        plan = list(goal_indices) if goal_indices else [None]
        if act is None:
            env.action_space.seed(seed)
            act = lambda obs: env.action_space.sample()  # noqa: E731
        bar = tqdm(total=steps * len(plan), desc="demo", unit="action")
        with bar:
            for k, goal_index in enumerate(plan):
                # Each episode from the initial shape, as Table I's with reinitialisation.
                options = {} if goal_index is None else {"goal_index": int(goal_index)}
                obs, info = env.reset(seed=seed if k == 0 else None, options=options)
                if start is not None:
                    start(env, obs)
                episode = Episode(who, goals, int(info["goal_index"]),
                                  env.unwrapped.threshold)
                recorded.append(play_rendered(env, act, obs, info, episode, steps, width,
                                              height, bar))
    finally:
        env.close()
    return save_demo(recorded, out, n_nodes, fps=fps, mp4=mp4)


def save_demo(episodes: Sequence[Episode], out: str | Path, n_nodes: int, fps: int = 10,
              mp4: bool = True) -> str:
    """Write the pictures of :func:`run_demo`: ``out`` (PNG of the first episode's first and
    last frames), a GIF of all episodes' captioned frames beside it (each episode's last
    frame held :data:`HOLD_SECONDS`), and an MP4 likewise if ``mp4`` and ffmpeg is there.

    Returns:
        one line per episode, then the files written.
    """
    out = Path(out)
    first = episodes[0]
    plot_episode_frames(first.frames[0], first.frames[-1],
                        (f"start: mean distance {first.distances[0]:.3f} m",
                         f"after {first.actions} actions: {first.distances[-1]:.3f} m"),
                        f"{first.who}, {n_nodes} nodes, goal {first.goal_index} of the "
                        f"{first.goals} goals (blue: P_c, red: P_d)", out=out)
    frames, hold = [], []
    for episode in episodes:
        frames += episode.captioned_frames()
        hold.append(len(frames) - 1)
    written = [out, save_gif(frames, out.with_suffix(".gif"), fps, hold, HOLD_SECONDS)]
    notes = []
    if mp4:
        try:
            video = save_mp4(frames, out.with_suffix(".mp4"), fps, hold, HOLD_SECONDS)
        except (OSError, RuntimeError) as err:  # a broken or limited ffmpeg: GIF is enough
            video, notes = None, [f"no MP4: {err}"]
        if video is not None:
            written.append(video)
    lines = [f"goal {e.goal_index}: {e.actions} actions, return {e.total_reward:.3f}, "
             f"mean distance {e.distances[0]:.4f} -> {e.distances[-1]:.4f} m, "
             f"success {e.success}" for e in episodes]
    return "\n".join(lines + notes + ["wrote " + ", ".join(map(str, written))])


__all__ = ["DEFAULT_AGENT_GOALS", "DEFAULT_GOAL_INDEX", "Episode", "play_rendered",
           "render_frame", "run_demo", "save_demo"]
