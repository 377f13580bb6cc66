"""``dlo-course demo``: one episode of the environment, saved as pictures.

The quickest way to see the task: a random policy, a goal from a database, the rendered robot
and rod with P_c (blue) and P_d (red) marked.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def save_gif(frames: list[np.ndarray], path: str | Path, fps: int = 10) -> Path:
    """Write RGB frames (H, W, 3) uint8 as an animated GIF (Pillow ships with matplotlib)."""
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(f) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps),
                   loop=0)
    return path


def run_demo(n_nodes: int = 4, goals: str = "small", steps: int = 30, seed: int = 0,
             out: str | Path = "reports/demo.png", policy=None) -> str:
    """Run one episode and save ``out`` (first | last frame) and a GIF beside it.

    Args:
        policy: a callable obs -> action; None for uniformly random actions.
    Returns:
        a one-line summary of the episode.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tqdm.auto import tqdm

    from dlo_course.env import DLOShapeEnv

    env = DLOShapeEnv(n_nodes=n_nodes, goals=goals, render_mode="rgb_array",
                      max_episode_steps=steps)
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
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.9))
    for ax, frame, title in zip(axes, (frames[0], frames[-1]),
                                (f"start: mean distance {start:.3f} m",
                                 f"after {len(frames) - 1} actions: {info['distance']:.3f} m")):
        ax.imshow(frame)
        ax.set_title(title)
        ax.axis("off")
    fig.suptitle(f"{n_nodes} nodes, goal {info['goal_index']} of the {goals} database "
                 "(blue: P_c, red: P_d)")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    gif = save_gif(frames, out.with_suffix(".gif"))
    return (f"{len(frames) - 1} actions, return {total:.3f}, final mean distance "
            f"{info['distance']:.4f} m, success {info['is_success']}; wrote {out} and {gif}")
