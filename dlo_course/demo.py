"""``dlo-course demo``: one episode of the environment, saved as pictures.

The quickest way to see the task: a random policy, a goal from a database, the rendered robot
and rod with P_c (blue) and P_d (red) marked.
"""

from __future__ import annotations

from pathlib import Path

from tqdm.auto import tqdm

from dlo_course.plots import plot_episode_frames, save_gif  # noqa: F401  (save_gif: old home)


def run_demo(n_nodes: int = 4, goals: str = "small", steps: int = 30, seed: int = 0,
             out: str | Path = "reports/demo.png", policy=None) -> str:
    """Run one episode and save ``out`` (first | last frame) and a GIF beside it.

    Args:
        policy: a callable obs -> action, e.g. ``functools.partial(policy_action, actor)``
            (:func:`dlo_course.ddpg.policy_action`); None for uniformly random actions.
    Returns:
        a one-line summary of the episode.
    """
    from dlo_course.env import make_env  # imports PyBullet: only when needed

    env = make_env(max_episode_steps=steps, n_nodes=n_nodes, goals=goals,
                   render_mode="rgb_array")
    try:
        obs, info = env.reset(seed=seed)
        env.action_space.seed(seed)
        frames = [env.render()]
        start = info["distance"]
        total = 0.0
        for _ in tqdm(range(steps), desc="demo episode", unit="action"):
            action = env.action_space.sample() if policy is None else policy(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            frames.append(env.render())
            if terminated or truncated:
                break
    finally:
        env.close()
    out = Path(out)
    plot_episode_frames(frames[0], frames[-1],
                        (f"start: mean distance {start:.3f} m",
                         f"after {len(frames) - 1} actions: {info['distance']:.3f} m"),
                        f"{n_nodes} nodes, goal {info['goal_index']} of the {goals} database "
                        "(blue: P_c, red: P_d)", out=out)
    gif = save_gif(frames, out.with_suffix(".gif"))
    return (f"{len(frames) - 1} actions, return {total:.3f}, final mean distance "
            f"{info['distance']:.4f} m, success {info['is_success']}; wrote {out} and {gif}")
