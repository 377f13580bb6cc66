"""Robustness: a trained agent (or a classical controller) in a world that is not the one it
was trained in, and domain randomisation to prepare it for that (the paper's future work,
sim-to-real; lesson 16).

A real rod is never exactly the simulated one: its stiffness, its mass and its damping are
known only roughly, and a camera sees its nodes with some error. This module makes both
kinds of mismatch measurable in simulation:

* **model mismatch**: :func:`dlo_course.randomisation.scale_params` scales physical
  parameters of the rod (:data:`dlo_course.randomisation.PERTURBABLE`: Young's modulus, mass,
  Neo-Hookean damping, edge damping) by factors relative to the training values, e.g.
  ``{"youngs_modulus": 1.3}`` for a rod 30% stiffer;
* **sensing noise**: :class:`ObservationNoise` adds seeded Gaussian noise to the observed node
  positions P_c, and to nothing else;
* :func:`evaluate_perturbed` runs the paper's test protocol
  (:func:`dlo_course.evaluation.evaluate_thresholds`) with both; ``dlo-course evaluate
  --perturb youngs_modulus=1.3 --obs-noise 0.005`` is the same from the command line;
* **domain randomisation** for training: ``DLOShapeEnv(randomize={"youngs_modulus": [0.7,
  1.3]})`` draws the factors uniformly in their ranges
  (:func:`dlo_course.randomisation.draw_factors`) at every reset
  that rebuilds the world, from a generator seeded by ``reset(seed=...)``; off by default.
  From the command line: ``dlo-course train --env-kwargs '{"randomize": {"mass": [0.8,
  1.2]}}'``.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import gymnasium as gym
import numpy as np

from dlo_course.randomisation import PERTURBABLE, scale_params, validate_factors
from dlo_course.task import TABLE_THRESHOLDS, TRAIN_THRESHOLD, ObservationLayout


# ------------------------------------------------------------------ model mismatch
def parse_perturbation(text: str) -> tuple[str, float]:
    """``"youngs_modulus=1.3"`` -> ``("youngs_modulus", 1.3)``, checked
    (:func:`validate_factors`); ValueError for anything else."""
    name, sep, value = str(text).partition("=")
    if not sep:
        raise ValueError(f"{text!r} is not NAME=FACTOR (e.g. youngs_modulus=1.3)")
    name = name.strip()
    try:
        factor = float(value)
    except ValueError:
        raise ValueError(f"the factor in {text!r} is not a number") from None
    return name, validate_factors({name: factor})[name]


# ------------------------------------------------------------------ sensing noise
def add_observation_noise(obs: np.ndarray, n_nodes: int, std: float,
                          rng: np.random.Generator) -> np.ndarray:
    """A copy of the observation(s) ``obs`` (..., 6 + 6m) with Gaussian noise of standard
    deviation ``std`` (m) added to the P_c slice only (``ObservationLayout(n_nodes).current``,
    :class:`dlo_course.task.ObservationLayout`): the tip's
    position and velocity and the goal P_d are left exactly as they were.

    The noise is one ``rng.normal(0, std, size)`` draw of the slice's shape; ``std == 0``
    returns an unchanged copy and draws nothing.

    Raises:
        ValueError: for a negative or non-finite ``std``, or an observation that does not
            have 6 + 6m components.
    """
    std = float(std)
    if not (math.isfinite(std) and std >= 0):
        raise ValueError(f"the noise standard deviation must be >= 0 (m), got {std}")
    noisy = np.array(obs, copy=True)
    layout = ObservationLayout(int(n_nodes))
    layout.check(noisy)
    if std == 0:
        return noisy
    part = layout.current
    noise = rng.normal(0.0, std, size=noisy[..., part].shape)
    noisy[..., part] = noisy[..., part] + noise
    return noisy


class ObservationNoise(gym.ObservationWrapper):
    """Gaussian noise of standard deviation ``std`` (m) on the observed node positions P_c of
    a ``DLOShape-v0`` environment, as a camera would add it.

    Only the P_c slice of the observation the *agent* sees is changed
    (:func:`add_observation_noise`); the tip state and the goal P_d are exact. The reward,
    ``terminated`` and ``info["distance"]`` are computed by the wrapped environment on the
    true node positions, so an episode succeeds when the real rod reaches its goal, not when
    the noisy measurement says so.

    Seeded: the noise generator starts from ``seed`` and is reseeded by ``reset(seed=s)``
    (from ``s``), so a seeded run always sees the same noise. ``std=0`` is the identity.
    """

    def __init__(self, env: gym.Env, std: float, seed: int | None = None) -> None:
        super().__init__(env)
        std = float(std)
        if not (math.isfinite(std) and std >= 0):
            raise ValueError(f"the noise standard deviation must be >= 0 (m), got {std}")
        self.std = std
        self.n_nodes = int(env.unwrapped.n_nodes)
        self.noise_rng = np.random.default_rng(seed)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            self.noise_rng = np.random.default_rng(seed)
        return super().reset(seed=seed, options=options)

    def observation(self, observation):
        noisy = add_observation_noise(observation, self.n_nodes, self.std, self.noise_rng)
        space = self.observation_space
        return np.clip(noisy, space.low, space.high).astype(space.dtype)


# ------------------------------------------------------------------ the test protocol
def evaluate_perturbed(agent, goals, thresholds: Sequence[float],
                       factors: Mapping[str, float] | None = None, obs_noise: float = 0.0,
                       noise_seed: int = 0, params=None, **kwargs) -> dict:
    """The paper's test protocol (:func:`dlo_course.evaluation.evaluate_thresholds`) in a
    perturbed world: the rod's parameters scaled by ``factors`` relative to ``params`` (the
    training values, :class:`~dlo_course.simulation.SimParams` by default) and Gaussian noise
    of ``obs_noise`` m on the observed P_c (:class:`ObservationNoise`, seeded by
    ``noise_seed`` + the MPI rank).

    ``agent`` is a trained agent or a :class:`~dlo_course.evaluation.Controller`, and
    ``kwargs`` the other arguments of ``evaluate_thresholds`` (``episodes``, ``seed``,
    ``reinitialize``...). The success test always uses the true node positions.

    With reinitialisation, repeated test goals are simulated once (as in the unperturbed
    protocol), so with noise they share one draw of it. With noise the world is rebuilt
    before every episode, rather than forked from one settled copy (:mod:`dlo_course.snapshot`),
    so that every episode starts through the wrapper (``run_traces`` sees the
    observation wrapper and does so): slower, the same episodes otherwise.

    Returns:
        ``evaluate_thresholds``' ``{threshold: (summary, records)}``.
    """
    from dlo_course import mpi
    from dlo_course.evaluation import evaluate_thresholds
    from dlo_course.simulation import SimParams

    factors = validate_factors(factors or {})
    obs_noise = float(obs_noise)
    if not (math.isfinite(obs_noise) and obs_noise >= 0):
        raise ValueError(f"the observation noise must be >= 0 (m), got {obs_noise}")
    scaled = scale_params(params or SimParams(), factors)
    if obs_noise == 0:
        return evaluate_thresholds(agent, goals, thresholds, env_kwargs={"params": scaled},
                                   **kwargs)
    seed = int(noise_seed) + mpi.rank()

    def wrapper(env):
        return ObservationNoise(env, obs_noise, seed=seed)
    return evaluate_thresholds(agent, goals, thresholds, env_kwargs={"params": scaled},
                               env_wrapper=wrapper, **kwargs)


# ------------------------------------------------------------------ the benchmark's files
NOMINAL = "nominal"
"""The parameter name of the unperturbed setting (every factor 1, no noise)."""
NOISE = "obs_noise"
"""The parameter name of the observation-noise settings (value: the noise's std in m)."""


def setting_file(out_dir, controller: str, parameter: str, value: float):
    """Where :func:`run_setting` keeps one setting's JSON: ``CONTROLLER_PARAMETER_VALUE.json``
    (``CONTROLLER_nominal.json`` for the unperturbed one)."""
    from pathlib import Path

    name = f"{controller}_{NOMINAL}" if parameter == NOMINAL else \
        f"{controller}_{parameter}_{value:g}"
    return Path(out_dir) / f"{name}.json"


def run_setting(agent, controller: str, parameter: str, value: float, out_dir,
                episodes: int = 20, seed: int = 0, goals: str = "small-test",
                thresholds: Sequence[float] = TABLE_THRESHOLDS, show_progress: bool = True
                ) -> dict:
    """Evaluate ``agent`` (a trained agent's folder or a Controller, called ``controller`` in
    the files) in one perturbed setting and write it as JSON: the paper's protocol with
    reinitialisation, ``episodes`` episodes on ``goals``, goal draw ``seed`` (the same goals
    in every setting), noise seed ``seed``.

    ``parameter`` is a name of :data:`PERTURBABLE` (``value``: its factor), :data:`NOISE`
    (``value``: the std in m) or :data:`NOMINAL`. A setting whose file exists with the same
    number of episodes is read back instead (the benchmark resumes).

    Returns:
        The setting's record: ``controller``, ``parameter``, ``value``, ``episodes``,
        ``seed``, ``goals``, ``wall_seconds``, ``summaries`` ({threshold as text: Table I's
        statistics}) and ``records`` ({threshold as text: every episode}).
    """
    import json
    import time
    from dataclasses import asdict

    path = setting_file(out_dir, controller, parameter, value)
    if path.is_file():
        kept = json.loads(path.read_text())
        if kept.get("episodes") == episodes and kept.get("seed") == seed:
            return kept
    if parameter == NOMINAL:
        factors, noise = {}, 0.0
    elif parameter == NOISE:
        factors, noise = {}, float(value)
    else:
        factors, noise = validate_factors({parameter: value}), 0.0
    start = time.perf_counter()
    results = evaluate_perturbed(agent, goals, thresholds, factors=factors, obs_noise=noise,
                                 noise_seed=seed, episodes=episodes, seed=seed,
                                 reinitialize=True, show_progress=show_progress)
    wall = time.perf_counter() - start
    if any(summary is None for summary, _ in results.values()):
        return {}  # not MPI rank 0
    record = {
        "controller": controller, "parameter": parameter, "value": float(value),
        "episodes": episodes, "seed": seed, "goals": goals, "reinitialize": True,
        "wall_seconds": round(wall, 1),
        "summaries": {f"{t:g}": s.as_dict() for t, (s, _) in results.items()},
        "records": {f"{t:g}": [asdict(r) for r in recs] for t, (_, recs) in results.items()},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=1))
    return record


def load_results(out_dir) -> list[dict]:
    """Every setting's record (:func:`run_setting`) kept in ``out_dir``, sorted by
    controller, then the training world first, each parameter of :data:`PERTURBABLE` by
    value, then the noise levels; an empty list if there are none."""
    import json
    from pathlib import Path

    records = []
    for path in sorted(Path(out_dir).glob("*.json")):
        data = json.loads(path.read_text())
        if {"controller", "parameter", "value", "summaries"} <= set(data):
            records.append(data)
    order = (NOMINAL, *PERTURBABLE, NOISE)

    def key(r):
        rank = order.index(r["parameter"]) if r["parameter"] in order else len(order)
        return r["controller"], rank, r["parameter"], r["value"]
    return sorted(records, key=key)


def curves(results: Sequence[dict], threshold: float = TRAIN_THRESHOLD) -> dict:
    """The robustness curves in ``results``: ``{(controller, parameter): rows}`` for every
    perturbed parameter (:data:`PERTURBABLE` or :data:`NOISE`), rows sorted by value, each
    ``(value, done %, Wilson 95% low, high, episodes)`` at ``threshold``. The nominal setting
    joins every curve of its controller, as factor 1 or noise 0."""
    from dlo_course.evaluation import wilson_interval

    key = f"{threshold:g}"
    points: dict = {}
    nominal = {}
    for r in results:
        summary = r["summaries"][key]
        n = summary["episodes"]
        done = round(summary["done_percent"] * n / 100)
        low, high = wilson_interval(done, n)
        row = (r["value"], 100.0 * done / n, 100.0 * low, 100.0 * high, n)
        if r["parameter"] == NOMINAL:
            nominal[r["controller"]] = row
        else:
            points.setdefault((r["controller"], r["parameter"]), []).append(row)
    for (controller, parameter), rows in points.items():
        if controller in nominal:
            base = nominal[controller]
            rows.append((0.0 if parameter == NOISE else 1.0, *base[1:]))
    return {k: sorted(set(rows)) for k, rows in sorted(points.items())}


def paired_difference(setting: dict, nominal: dict, threshold: float = TRAIN_THRESHOLD
                      ) -> tuple[float, float, float, int]:
    """How much one setting changes done % at ``threshold``, against the training world, on the
    same episodes: ``(difference, low, high, discordant)`` in percentage points, with a 95%
    interval for paired proportions, and the number of episodes whose outcome differs between
    the two worlds.

    Both records come from :func:`run_setting` with the same goal draw, so episode i plays the
    same goal in both: comparing episode by episode removes the goals' own spread (an easy goal
    is easy in both worlds), and the interval is much narrower than two Wilson intervals side
    by side. The interval is Newcombe's for paired data (his method 10, Statistics in Medicine
    17, 1998): each setting's Wilson interval, combined with the correlation of the two
    worlds' outcomes. Unlike a bootstrap it stays a few points wide when no episode changed
    (100 episodes cannot show that nothing changes), and it needs no random draw.

    Raises:
        ValueError: if either record has no episodes at ``threshold`` (records written before
            they were kept) or the two did not play the same goals.
    """
    from dlo_course.evaluation import wilson_interval

    key = f"{threshold:g}"
    outcomes = []
    for record in (setting, nominal):
        episodes = record.get("records", {}).get(key)
        if not episodes:
            raise ValueError(f"{record.get('controller')}, {record.get('parameter')}: no "
                             f"episodes kept at {key} m (rerun it with benchmarks/robustness.py)")
        outcomes.append({e["episode"]: (e["goal_index"], bool(e["done"])) for e in episodes})
    changed, base = outcomes
    if {i: g for i, (g, _) in changed.items()} != {i: g for i, (g, _) in base.items()}:
        raise ValueError("the two settings did not play the same goals: pair only settings of "
                         "one goal draw")
    pairs = [(changed[i][1], base[i][1]) for i in base]
    n = len(pairs)
    both = sum(x and y for x, y in pairs)
    gained = sum(x and not y for x, y in pairs)   # reached only in the changed world
    lost = sum(y and not x for x, y in pairs)     # reached only in the training world
    neither = n - both - gained - lost
    p1, p2 = (both + gained) / n, (both + lost) / n
    (l1, u1), (l2, u2) = wilson_interval(both + gained, n), wilson_interval(both + lost, n)
    margins = (both + gained) * (lost + neither) * (both + lost) * (gained + neither)
    phi = (both * neither - gained * lost) / math.sqrt(margins) if margins else 0.0
    below = math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    above = math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    diff = p1 - p2
    return 100.0 * diff, 100.0 * (diff - below), 100.0 * (diff + above), gained + lost


def paired_changes(results: Sequence[dict], threshold: float = TRAIN_THRESHOLD) -> list[dict]:
    """Every perturbed setting of ``results`` against its controller's training world
    (:func:`paired_difference`): dicts with ``controller``, ``parameter``, ``value``,
    ``difference``, ``low``, ``high``, ``discordant`` and ``told_apart`` (the interval
    excludes 0). Settings without a training world of their controller are left out."""
    nominal = {r["controller"]: r for r in results if r["parameter"] == NOMINAL}
    rows = []
    for r in results:
        if r["parameter"] == NOMINAL or r["controller"] not in nominal:
            continue
        diff, low, high, discordant = paired_difference(r, nominal[r["controller"]], threshold)
        rows.append({"controller": r["controller"], "parameter": r["parameter"],
                     "value": r["value"], "difference": diff, "low": low, "high": high,
                     "discordant": discordant, "told_apart": high < 0 or low > 0})
    return rows


def change_label(parameter: str, value: float) -> str:
    """How a setting reads in a table: ``"mass x 1.3"``, ``"noise on P_c, std 5 mm"``."""
    if parameter == NOMINAL:
        return "none (training world)"
    if parameter == NOISE:
        return f"noise on P_c, std {1000 * value:g} mm"
    return f"{parameter} x {value:g}"


def changes_table(results: Sequence[dict], threshold: float = TRAIN_THRESHOLD) -> str:
    """A Markdown table of :func:`paired_changes`: each setting's change of done % at
    ``threshold`` from the training world, with its paired 95% interval."""
    lines = [f"| controller | change | done % at {threshold:g} m minus the training world's "
             "(paired 95% CI) | episodes that changed outcome | told apart from the "
             "training world |", "|---|---|---|---|---|"]
    for row in paired_changes(results, threshold):
        lines.append(f"| {row['controller']} | {change_label(row['parameter'], row['value'])} | "
                     f"{row['difference']:+.0f} ({row['low']:+.0f} to {row['high']:+.0f}) | "
                     f"{row['discordant']} | {'yes' if row['told_apart'] else 'no'} |")
    return "\n".join(lines)


def results_table(results: Sequence[dict], thresholds: Sequence[float] = TABLE_THRESHOLDS
                  ) -> str:
    """A Markdown table of ``results``: one row per setting, done % with its Wilson 95%
    interval and the mean final distance at each threshold."""
    head = "| controller | change | episodes | " + " | ".join(
        f"done % at {t:g} m (95% CI) | mean final distance at {t:g} m" for t in thresholds)
    lines = [head + " |", "|---|---|---|" + "---|---|" * len(thresholds)]
    for r in results:
        change = change_label(r["parameter"], r["value"])
        cells = []
        for t in thresholds:
            s = r["summaries"][f"{t:g}"]
            cells.append(f"{s['done_percent']:.0f} ({s['done_ci_low']:.0f}-"
                         f"{s['done_ci_high']:.0f}) | {s['mean_distance']:.4f} m")
        lines.append(f"| {r['controller']} | {change} | {r['episodes']} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_results(results: Sequence[dict], out=None, threshold: float = TRAIN_THRESHOLD):
    """Done % at ``threshold`` against each change (one panel per perturbed parameter, one
    line per controller), with Wilson 95% intervals; saved to ``out`` when given.

    Returns:
        The matplotlib figure.
    """
    import matplotlib.pyplot as plt

    data = curves(results, threshold)
    parameters = [p for p in (*PERTURBABLE, NOISE) if any(k[1] == p for k in data)]
    fig, axes = plt.subplots(1, max(1, len(parameters)),
                             figsize=(4.2 * max(1, len(parameters)), 3.8), squeeze=False)
    for ax, parameter in zip(axes[0], parameters):
        for (controller, param), rows in data.items():
            if param != parameter:
                continue
            x = np.array([r[0] for r in rows]) * (1000 if parameter == NOISE else 1)
            y = np.array([r[1] for r in rows])
            err = np.clip([[r[1] - r[2] for r in rows], [r[3] - r[1] for r in rows]],
                          0, None)  # the interval's ends may miss 0 or 100 by 1e-14
            ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=controller)
        ax.set_xlabel("noise std on P_c (mm)" if parameter == NOISE
                      else f"{parameter} factor (1 = training)")
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel(f"done % at {threshold:g} m (Wilson 95%)")
    if parameters:
        axes[0][0].legend()
    fig.tight_layout()
    if out is not None:
        from pathlib import Path

        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120)
    return fig
