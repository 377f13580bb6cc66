"""The ``dlo-course`` command line.

Each subcommand is a thin wrapper: it parses flags and calls one library function, so the
lessons and the command line always run the same code. Its choices and the defaults in its help
come from the library (the configuration dataclasses, the presets, the goal sources), never
restated here. Heavy modules (torch, pybullet) are imported inside the commands to keep
``dlo-course --help`` instant: :mod:`dlo_course.config` imports neither.
"""

from __future__ import annotations

import dataclasses
import json
import re
import typing
from pathlib import Path
from typing import Any, Callable

import click

from dlo_course.config import (PRESET_SUMMARIES, PRESETS, DDPGConfig, TrainConfig,
                               config_fields, experiment_config, field_docs, field_types,
                               paper_default, preset_table, read_toml)
from dlo_course.database import BOXES, GOAL_SOURCES, DatabaseError
from dlo_course.mpi_env import import_pybullet_quietly
from dlo_course.paths import DATA_DIR
from dlo_course.task import DEFAULT_N_NODES, NODE_COUNTS, TRAIN_THRESHOLD

PRESET_NAMES = click.Choice(list(PRESETS))


class NodeCount(click.Choice):
    """``--nodes`` of every command: one of :data:`dlo_course.task.NODE_COUNTS`, as an int
    (typed "4" or given 4)."""

    def __init__(self) -> None:
        super().__init__([str(n) for n in NODE_COUNTS])

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> int:
        return int(super().convert(str(value), param, ctx))


NODES = NodeCount()
TIME_MODES = click.Choice(["code", "paper"])  # SimParams.time_mode; simulation imports PyBullet


def _paper(config_class: type, name: str) -> str:
    """"[preset; the paper: X]" for a ``train`` option that overrides a preset's field."""
    value = paper_default(config_class, name)
    if isinstance(value, bool):
        value = "on" if value else "off"
    return f"[preset; the paper: {value}]"


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def main() -> None:
    """dlo-course: deep RL for the shape control of deformable linear objects."""
    import_pybullet_quietly()  # under mpiexec: PyBullet's banner from rank 0 only


@main.command()
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              default=DATA_DIR / "rod.vtk", show_default=True, help="VTK file to write.")
def mesh(out: Path) -> None:
    """Generate the paper's tetrahedral rod mesh (200 nodes, 392 tetrahedra)."""
    from dlo_course.mesh import make_rod_mesh, write_vtk

    m = make_rod_mesh()
    write_vtk(m, out)
    click.echo(f"wrote {out}: {len(m.points)} nodes, {len(m.tets)} tetrahedra, "
               f"{len(m.edges)} edges, {len(m.surface_triangles)} surface triangles")


@main.command()
@click.option("--box", type=click.Choice(list(BOXES)), required=True,
              help="Which deformation box of the paper to sweep.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Output .npz (default: data/databases/BOX.npz).")
@click.option("--settle", "settle_steps", type=click.IntRange(min=0), default=None,
              help="Record with the settled protocol, holding the tip still for this many "
                   "actions before each record (the first round used 15). Default: the "
                   "authors' sweep, a snapshot 6 ms after every move.")
@click.option("--time-mode", type=TIME_MODES, default="code",
              show_default=True, help="Time per action of the settled protocol "
                                      "(see SimParams.time_mode).")
@click.option("--limit", type=int, default=None,
              help="Stop after this many deformations (for a quick look; the file is partial).")
def database(box: str, out: Path | None, settle_steps: int | None, time_mode: str,
             limit: int | None) -> None:
    """Sweep the tip through a paper box and record every deformation (Fig. 3).

    The small box takes about 5 minutes on one core, the large one about 11 (docs/design.md,
    "The deformation databases")."""
    from dlo_course.database import generate_database

    path = generate_database(box, out=out, settle_steps=settle_steps, time_mode=time_mode,
                             limit=limit, progress=True)
    click.echo(f"wrote {path}")


@main.command("plot-boxes")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("reports/fig3_boxes.png"), show_default=True)
def plot_boxes(out: Path) -> None:
    """Draw both deformation boxes and the recorded tip positions (the paper's Fig. 3)."""
    from dlo_course.plots import plot_databases

    try:
        plot_databases(out=out)
    except (DatabaseError, FileNotFoundError) as err:
        raise click.ClickException(str(err)) from None
    click.echo(f"wrote {out}")


@main.command()
@click.option("--agent", type=click.Path(path_type=Path), default=None,
              help="Watch a trained agent (a run directory or agent folder holding actor.pt, "
                   "or the file), e.g. data/checkpoints/nodes4. Default: random actions.")
# The names of CONTROLLER_NAMES below (defined with the evaluate command).
@click.option("--controller", type=click.Choice(["jacobian"]), default=None,
              help="Watch a classical controller instead (dlo_course.jacobian).")
@click.option("--nodes", "n_nodes", type=NODES, default=None,
              help=f"Number of selected mesh nodes [the agent's; else {DEFAULT_N_NODES}].")
@click.option("--goals", "--database", "goals", type=click.Choice(GOAL_SOURCES),
              default=None, help="Goal set: a whole database, or the paper's test goals "
              "drawn from it [small; with --agent or --controller: small-test].")
@click.option("--goal-index", "goal_indices", type=click.IntRange(min=0), multiple=True,
              help="Goal of an episode; repeat it for several episodes [with --agent or "
                   "--controller: 15, a small-test goal the shipped 4-node agent reaches; "
                   "else drawn from --seed].")
@click.option("--episodes", type=click.IntRange(min=1), default=None,
              help="Instead of --goal-index: this many episodes on the goals the evaluation "
                   "draws with --seed.")
@click.option("--steps", type=click.IntRange(1, 10_000), default=30, show_default=True,
              help="At most this many actions per episode.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--width", type=click.IntRange(min=16), default=None,
              help="Frame width in pixels [480].")
@click.option("--height", type=click.IntRange(min=16), default=None,
              help="Frame height in pixels [360].")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("reports/demo.png"), show_default=True,
              help="PNG of the first and last frames; a GIF of every episode is written "
                   "beside it, and an MP4 if ffmpeg is installed.")
def demo(agent: Path | None, controller: str | None, n_nodes: int | None, goals: str | None,
         goal_indices: tuple[int, ...], episodes: int | None, steps: int, seed: int,
         width: int | None, height: int | None, out: Path) -> None:
    """Render episodes headless (random actions, a trained agent or a controller) and save
    pictures and a video of them, P_c and P_d marked, the mean node distance on every frame."""
    from dlo_course.demo import run_demo

    if agent is not None and controller is not None:
        raise click.UsageError("give --agent or --controller (not both)")
    if goal_indices and episodes:
        raise click.UsageError("give --goal-index or --episodes (not both)")
    try:
        summary = run_demo(n_nodes=n_nodes, goals=goals,
                           steps=steps, seed=seed, out=out, agent=agent,
                           controller=controller, goal_indices=goal_indices,
                           episodes=episodes, width=width, height=height)
    except (DatabaseError, FileNotFoundError, ValueError) as err:  # TrainedAgentError too
        raise click.ClickException(str(err)) from None
    click.echo(summary)


@main.group()
def bench() -> None:
    """Speed measurements (benchmarks, not tests)."""


@bench.command("env")
@click.option("--steps", type=int, default=40, show_default=True,
              help="Actions timed per time setting.")
@click.option("--paper-steps", type=int, default=4, show_default=True,
              help="Actions timed for the (20x slower) paper time setting.")
@click.option("--seed", type=int, default=0, show_default=True)
def bench_env(steps: int, paper_steps: int, seed: int) -> None:
    """Actions per second of one environment, and where a step's time goes."""
    from dlo_course.bench import bench_env as run

    run(steps=steps, paper_steps=paper_steps, seed=seed)


@bench.command("scene")
@click.option("--actions", type=click.IntRange(1), default=60, show_default=True,
              help="Random tip moves every scene makes.")
@click.option("--block", type=click.IntRange(1), default=10, show_default=True,
              help="Moves per scene before the next scene's turn.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--switches", is_flag=True,
              help="Add rows that switch off the course's differences one at a time.")
@click.option("--knobs", is_flag=True,
              help="Add rows that try PyBullet settings on the course's scene.")
@click.option("--plane-contact", is_flag=True,
              help="Leave the rod-plane contact on in the authors' scene (it explodes).")
def bench_scene(actions: int, block: int, seed: int, switches: bool, knobs: bool,
                plane_contact: bool) -> None:
    """The course's scene against a minimal scene with the authors' settings, interleaved."""
    from dlo_course.scene_bench import bench_scene as run

    run(actions=actions, block=block, seed=seed, switch_table=switches, knob_table=knobs,
        plane_contact=plane_contact)


# --- train's options, generated from the configuration dataclasses ---

# The flags that existed before the options were generated keep their names; every field
# also has its own, --field-name.
_FLAG_ALIASES = {"env_id": ["--env"], "out_dir": ["--out"]}
_BOOL_FLAGS = {"reset_between_episodes": "--reset-between-episodes/--keep-shape"}
_HELP_DEFAULTS = {"out_dir": "[runs/PRESET_ENV_nNODES_seedSEED]"}
_HELP_NOTES = {
    "env_id": "Changing it drops the preset's environment arguments.",
    "env_kwargs": "A JSON object, e.g. '{\"goals\": \"large\"}', merged into the preset's.",
    "hidden_sizes": "Comma-separated, e.g. 256,256,256.",
}
_CONFIG_PARAMS: dict[str, str | None] = {}
"""train's generated parameters: field name -> section (None: TrainConfig, "ddpg")."""


class _IntList(click.ParamType):
    """Comma-separated integers, e.g. hidden layer widths."""

    name = "INTS"

    def convert(self, value: Any, param: Any, ctx: Any) -> tuple[int, ...]:
        if isinstance(value, tuple):
            return value
        try:
            return tuple(int(part) for part in str(value).split(","))
        except ValueError:
            self.fail(f"{value!r} is not a comma-separated list of integers", param, ctx)


class _JsonObject(click.ParamType):
    """A JSON object, e.g. an environment's keyword arguments."""

    name = "JSON"

    def convert(self, value: Any, param: Any, ctx: Any) -> dict[str, Any]:
        if isinstance(value, dict):
            return value
        try:
            parsed = json.loads(value)
        except ValueError as err:
            self.fail(f"{value!r} is not JSON: {err}", param, ctx)
        if not isinstance(parsed, dict):
            self.fail(f"{value!r} is not a JSON object ({{...}})", param, ctx)
        return parsed


class _Cleared:
    """The value of an optional field's option given as 'none': set the field to None (an
    option's None means that it was not given)."""

    def __repr__(self) -> str:
        return "none"


_CLEARED = _Cleared()


class _OrNone(click.ParamType):
    """An optional field's type: its value, or 'none'."""

    def __init__(self, inner: click.ParamType) -> None:
        self.inner = inner
        self.name = f"{inner.name}|none"

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        if value is _CLEARED or value == "none":
            return _CLEARED
        return self.inner.convert(value, param, ctx)


def _range_type(kind: type, bounds: tuple | None) -> click.ParamType:
    if bounds is None:
        return click.INT if kind is int else click.FLOAT
    low, high, low_open = bounds
    if kind is int:
        return click.IntRange(min=low, max=high, min_open=low_open)
    return click.FloatRange(min=low, max=high, min_open=low_open)


def _first_sentence(doc: str) -> str:
    """A field docstring's first sentence, without reStructuredText's markup (the first two
    for a switch documented as "True: ... False: ...")."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"\1", " ".join(doc.split())).replace("``", "")
    sentences = re.split(r"(?<=\.)\s+(?=[A-Z(])", text)
    return " ".join(sentences[:2] if sentences[0].startswith("True:") else sentences[:1])


def _config_option(config_class: type, f: dataclasses.Field) -> Callable:
    """The click option of one configuration field."""
    kind = field_types(config_class)[f.name]
    optional = type(None) in typing.get_args(kind)
    if optional:
        kind = next(k for k in typing.get_args(kind) if k is not type(None))
    flag = "--" + f.name.replace("_", "-")
    names = _FLAG_ALIASES.get(f.name, []) + [flag]
    if kind is bool:
        names = [_BOOL_FLAGS.get(f.name, f"{flag}/--no-{f.name.replace('_', '-')}")]
        param_type: click.ParamType | None = None
    elif "choices" in f.metadata:
        param_type = click.Choice(f.metadata["choices"])
    elif f.name == "out_dir":
        param_type = click.Path(file_okay=False)
    elif kind in (int, float):
        param_type = _range_type(kind, f.metadata.get("range"))
    elif typing.get_origin(kind) is tuple:
        param_type = _IntList()
    elif typing.get_origin(kind) is dict:
        param_type = _JsonObject()
    else:
        param_type = click.STRING
    note = _HELP_NOTES.get(f.name, "")
    if optional and param_type is not None:
        param_type = _OrNone(param_type)
        note = "'none' for None."
    doc = field_docs(config_class).get(f.name, "")
    default = _HELP_DEFAULTS.get(f.name) or _paper(config_class, f.name)
    help_text = " ".join(p for p in (_first_sentence(doc), note, default) if p)
    return click.option(*names, f.name, type=param_type, default=None, help=help_text)


def _config_options(command: Callable) -> Callable:
    """Add an option for every field of TrainConfig and DDPGConfig to ``command``."""
    options = []
    for section, config_class in ((None, TrainConfig), ("ddpg", DDPGConfig)):
        for f in config_fields(config_class):
            if f.name in _CONFIG_PARAMS:
                raise RuntimeError(f"two configuration fields are named {f.name!r}: "
                                   "their options would clash")
            _CONFIG_PARAMS[f.name] = section
            options.append(_config_option(config_class, f))
    for option in reversed(options):  # decorators apply bottom-up
        command = option(command)
    return command


def _list_presets(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    if value and not ctx.resilient_parsing:
        click.echo(preset_table())
        ctx.exit()


def train_config(preset_name: str | None, config_file: Path | None, nodes: int | None,
                 options: dict[str, Any]) -> tuple[str, TrainConfig]:
    """The preset's name and the configuration ``dlo-course train`` runs with: the preset,
    overridden by ``config_file`` (TOML), overridden by ``options`` (train's generated
    options by field name, None where not given) and ``--nodes``.

    Without an ``out_dir`` from the file or the flags, the run directory is
    ``runs/PRESET_ENV_nNODES_seedSEED``. Raises ``ValueError`` with what is wrong."""
    flags: dict[str, Any] = {}
    for field_name, value in options.items():
        if value is None:
            continue
        value = None if value is _CLEARED else value
        section = _CONFIG_PARAMS[field_name]
        (flags.setdefault(section, {}) if section else flags)[field_name] = value
    if nodes is not None:
        flags["env_kwargs"] = {**flags.get("env_kwargs", {}), "n_nodes": nodes}
    file_settings = read_toml(config_file) if config_file is not None else {}
    name, config, given = experiment_config(preset_name, file_settings, flags,
                                            file_label=str(config_file))
    if "out_dir" not in given:
        nodes_part = f"_n{config.env_kwargs['n_nodes']}" if "n_nodes" in config.env_kwargs \
            else ""
        config = dataclasses.replace(config, out_dir=str(
            Path("runs") / f"{name}_{config.env_id}{nodes_part}_seed{config.seed}"))
    return name, config


# --- learning: train / plot (DDPG + MPI trainer) ---


@main.command()
@click.option("--preset", "preset_name", type=PRESET_NAMES, default=None,
              help="Starting configuration: " + "; ".join(
                  f"{name} ({summary})" for name, summary in PRESET_SUMMARIES.items())
              + ". --config and the flags below override it. [the file's preset, else smoke]")
@click.option("--config", "config_file", type=click.Path(exists=True, dir_okay=False,
                                                         path_type=Path), default=None,
              help="A TOML file of settings named as in config.json (a [ddpg] table for "
                   "the DDPG ones, an [env_kwargs] table, and preset = \"NAME\" for the "
                   "preset). It overrides the preset; the flags override it.")
@click.option("--list-presets", is_flag=True, expose_value=False, is_eager=True,
              callback=_list_presets, help="Print the presets with their summaries and exit.")
@click.option("--nodes", type=NODES, default=None,
              help="Rod nodes to control: env_kwargs' n_nodes [the preset's: " + ", ".join(
                  f"{name} {config.env_kwargs['n_nodes']}" for name, config in PRESETS.items()
                  if "n_nodes" in config.env_kwargs) + "].")
@_config_options
@click.option("--resume", is_flag=True, help="Continue the run in --out from its resume state.")
@click.option("--overwrite", is_flag=True, help="Start afresh even if --out holds a run.")
@click.option("--print-config", is_flag=True,
              help="Print the configuration these options give, as JSON, and exit.")
@click.option("--tensorboard", is_flag=True,
              help="Also write progress.csv's scalars (and validation's) for TensorBoard, in "
                   "RUN/tensorboard (needs the tensorboard package: the tensorboard extra).")
@click.option("--progress/--no-progress", default=True, show_default=True,
              help="Progress bar (rank 0).")
def train(preset_name: str | None, config_file: Path | None, nodes: int | None, resume: bool,
          overwrite: bool, print_config: bool, tensorboard: bool, progress: bool,
          **settings: Any) -> None:
    """Train DDPG agents; run under `mpiexec -n N` for N parallel agents (the paper: 32).

    Every field of the configuration has an option (help: its docstring's first sentence).
    Precedence: flags, then --config, then --preset."""
    try:
        name, config = train_config(preset_name, config_file, nodes, settings)
    except ValueError as err:
        raise click.UsageError(str(err)) from None
    if print_config:
        click.echo(json.dumps({"preset": name, "config": config.to_dict()}, indent=2))
        return

    from dlo_course import mpi
    from dlo_course.trainer import TensorBoardLogger, train as run_training

    try:
        loggers = [TensorBoardLogger()] if tensorboard else []
        run_dir = run_training(config, resume=resume, progress=progress, overwrite=overwrite,
                               loggers=loggers)
    except (ValueError, FileExistsError, ImportError) as err:
        raise click.ClickException(str(err)) from err
    if mpi.is_root():
        click.echo(f"trained {mpi.size()} agent(s); results in {run_dir}")


@main.command()
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.argument("dest", type=click.Path(file_okay=False, path_type=Path))
@click.option("--actor", type=click.Choice(["latest", "best"]), default="latest",
              show_default=True,
              help="Ship the run's last actor, or the one that did best on its validation "
                   "goals (runs trained with --validate-every).")
def ship(run_dir: Path, dest: Path, actor: str) -> None:
    """Copy a training run's agent and record into DEST (e.g. data/checkpoints/nodes4),
    without its resume state (replay buffers)."""
    from dlo_course.rundir import ship_run

    try:
        ship_run(run_dir, dest, actor=actor)
    except (ValueError, FileNotFoundError) as err:
        raise click.ClickException(str(err)) from err
    click.echo(f"shipped the {actor} actor of {run_dir} to {dest}")


@main.command()
@click.argument("run_dirs", nargs=-1, required=True,
                type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("reports/learning_curves.png"), show_default=True)
@click.option("--label", "labels", multiple=True,
              help="Legend label, once per run directory (per group of seeds with "
                   "--aggregate-seeds), in order [from each run's config].")
@click.option("--x", "x_axis", type=click.Choice(["episode", "transitions"]),
              default="episode", show_default=True,
              help="Draw against episodes per agent, or transitions of all agents.")
@click.option("--aggregate-seeds", is_flag=True,
              help="One curve per group of runs that differ only by seed: the mean over the "
                   "seeds and a band of one standard deviation.")
def plot(run_dirs: tuple[Path, ...], out: Path, labels: tuple[str, ...], x_axis: str,
         aggregate_seeds: bool) -> None:
    """Learning curves of training runs, like the paper's Fig. 4."""
    from dlo_course.plots import plot_learning_curves

    try:
        plot_learning_curves(run_dirs, out=out, labels=labels or None, x=x_axis,
                             aggregate_seeds=aggregate_seeds)
    except (ValueError, FileNotFoundError) as err:
        raise click.ClickException(str(err)) from err
    click.echo(f"wrote {out}")


# --- evaluation and reproduction ---
# dlo_course.jacobian.CONTROLLERS (restated: that module imports torch and PyBullet)
CONTROLLER_NAMES = click.Choice(["jacobian"])


@main.command()
@click.option("--agent", "--checkpoint", "agent", type=click.Path(path_type=Path),
              default=None, help="Trained agent: a run directory or agent folder holding "
                                 "actor.pt, or the actor.pt file (--checkpoint: the old name).")
@click.option("--controller", "controller_name", type=CONTROLLER_NAMES, default=None,
              help="Instead of --agent, a classical controller: 'jacobian', shape servoing "
                   "with an online deformation Jacobian (dlo_course.jacobian), for --nodes "
                   f"[{DEFAULT_N_NODES}] nodes.")
@click.option("--database", "goals", default="small", show_default=True,
              help="Goals: 'small-test' or 'large-test' (the goals of the paper's Table I), "
                   "'small' or 'large' (the whole database), a database .npz, or a .npy "
                   "array (K, nodes, 3).")
@click.option("--threshold", "thresholds", type=click.FloatRange(min=0, min_open=True),
              multiple=True, help=f"Success distance (m) [{TRAIN_THRESHOLD}]. Repeat it to score the same "
              "goals at several thresholds: with reinitialisation the episodes are then run "
              "once, at the smallest.")
@click.option("--no-reinit", is_flag=True,
              help="Start each episode from the shape the previous one ended in.")
@click.option("--episodes", type=click.IntRange(min=1), default=1000, show_default=True)
@click.option("--max-steps", type=click.IntRange(min=1), default=30, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed of the goal draw.")
@click.option("--nodes", "n_nodes", type=NODES, default=None,
              help="Nodes the agent must have been trained for, or the controller's "
                   f"[the agent's; else {DEFAULT_N_NODES}].")
@click.option("--time-mode", type=TIME_MODES, default="code", show_default=True)
@click.option("--perturb", "perturbations", multiple=True, metavar="NAME=FACTOR",
              help="Test in a perturbed world: scale a parameter of the rod relative to "
                   "training, e.g. youngs_modulus=1.3 (names: youngs_modulus, mass, damping, "
                   "edge_damping); repeat it for several (dlo_course.robustness).")
@click.option("--obs-noise", type=float, default=0.0, show_default=True,
              help="Std (m) of Gaussian noise on the observed node positions P_c (the "
                   "success test uses the true positions); seeded by --seed.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the summary and every episode as JSON.")
def evaluate(agent: Path | None, controller_name: str | None, goals: str,
             thresholds: tuple[float, ...], no_reinit: bool, episodes: int, max_steps: int,
             seed: int, n_nodes: int | None, time_mode: str, perturbations: tuple[str, ...],
             obs_noise: float, out: Path | None) -> None:
    """The paper's test protocol (Table I) for one trained agent or a classical controller;
    parallel under mpiexec."""
    import json
    from dataclasses import asdict

    from dlo_course.evaluation import TrainedAgentError
    from dlo_course.robustness import evaluate_perturbed, parse_perturbation

    if (agent is None) == (controller_name is None):
        raise click.UsageError("give --agent or --controller (not both)")
    try:
        factors = dict(parse_perturbation(text) for text in perturbations)
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="--perturb") from None
    if not obs_noise >= 0:  # also refuses nan
        raise click.BadParameter(f"the noise std must be >= 0 (m), got {obs_noise}",
                                 param_hint="--obs-noise")
    if controller_name is not None:
        from dlo_course.jacobian import CONTROLLERS

        n_nodes = n_nodes or DEFAULT_N_NODES
        agent = CONTROLLERS[controller_name](n_nodes)
    thresholds = thresholds or (TRAIN_THRESHOLD,)
    try:
        results = evaluate_perturbed(agent, goals, thresholds, factors=factors,
                                     obs_noise=obs_noise, noise_seed=seed,
                                     reinitialize=not no_reinit, episodes=episodes,
                                     max_steps=max_steps, seed=seed,
                                     n_nodes=n_nodes,
                                     time_mode=time_mode)
    except (TrainedAgentError, FileNotFoundError, ValueError) as err:
        raise click.ClickException(str(err)) from None
    written = {}
    for threshold, (s, records) in results.items():
        if s is None:  # not rank 0
            return
        click.echo(f"{'with' if not no_reinit else 'without'} reinitialization, {goals} "
                   f"goals, threshold {threshold} m, {s.episodes} episodes of at most "
                   f"{max_steps} steps")
        if factors or obs_noise:
            click.echo("perturbed: " + ", ".join(
                [f"{name} x {f:g}" for name, f in factors.items()]
                + ([f"noise std {obs_noise:g} m on P_c"] if obs_noise else [])))
        click.echo(f"done {s.done_percent:.1f}% (95% CI {s.done_ci_low:.1f}-"
                   f"{s.done_ci_high:.1f}), final distance {s.mean_distance:.5f} +- "
                   f"{s.std_distance:.5f} m, best {s.best_distance:.5f} m")
        written[threshold] = {"threshold": threshold, "summary": s.as_dict(),
                              "episodes": [asdict(r) for r in records]}
        if factors or obs_noise:
            written[threshold]["perturbation"] = {"factors": factors, "obs_noise": obs_noise}
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        # One threshold: {"summary", "episodes"}; several: a list of those, with "threshold".
        data = next(iter(written.values())) if len(written) == 1 else list(written.values())
        out.write_text(json.dumps(data, indent=1))
        click.echo(f"wrote {out}")


# --- course: release / grade ---


@main.group("course")
def course_group() -> None:
    """The lesson notebooks: generate lessons/ from solutions/, grade students' notebooks."""


@course_group.command("release")
@click.option("--solutions", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Solution notebooks [the repository's solutions/].")
@click.option("--lessons", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder to write the student notebooks to [the repository's lessons/].")
@click.option("--check", is_flag=True,
              help="Write nothing; fail if lessons/ differs from what release would write.")
@click.option("--student", "student_dir", type=click.Path(file_okay=False, path_type=Path),
              default=None,
              help="Instead, write the student bundle to this new folder: the repository "
                   "with fresh lessons/, without solutions/ and the tests that hold answers.")
@click.option("--tests", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="With --student: the grading tests folder, inside the "
                                 "repository [the repository's tests/grading].")
def course_release(solutions: Path | None, lessons: Path | None, check: bool,
                   student_dir: Path | None, tests: Path | None) -> None:
    """Write lessons/ from solutions/: solutions replaced by NotImplementedError, no outputs."""
    from dlo_course.grading.bundle import release_student
    from dlo_course.grading.notebooks import (GRADING_TESTS_DIR, LESSONS_DIR, SOLUTIONS_DIR,
                                              exercises, release)

    solutions = solutions or SOLUTIONS_DIR
    lessons = lessons or LESSONS_DIR
    if tests is not None and student_dir is None:
        raise click.UsageError("--tests only applies to a student bundle (--student DIR)")
    if student_dir is not None:
        if check or lessons != LESSONS_DIR:
            raise click.UsageError("--student writes a whole bundle: no --check or --lessons")
        try:
            files = release_student(student_dir, solutions=solutions,
                                    tests=tests or GRADING_TESTS_DIR)
        except (ValueError, FileNotFoundError) as err:
            raise click.ClickException(str(err)) from err
        click.echo(f"wrote the student bundle to {student_dir}: {len(files)} files, without "
                   f"solutions/ and the tests that hold answers")
        return
    try:
        result = release(solutions, lessons, check=check)
    except (ValueError, FileNotFoundError) as err:
        raise click.ClickException(str(err)) from err
    if check:
        if result:
            raise click.ClickException("lessons are out of date; run `dlo-course course "
                                       "release`:\n  " + "\n  ".join(result))
        click.echo(f"{lessons} is up to date with {solutions}")
        return
    graded = exercises(solutions)
    written = sum(1 for e in graded if e.get("kind") == "text")
    click.echo(f"wrote {len(result)} notebooks ({len(graded) - written} exercises, {written} "
               f"written answers) to {lessons}")


@course_group.command("grade")
@click.argument("submissions", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("grades.csv"), show_default=True, help="CSV file of the grades.")
@click.option("--tests", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Grading tests [the repository's tests/grading].")
@click.option("--timeout", type=float, default=1800, show_default=True,
              help="Seconds allowed for one student's whole grading run.")
@click.option("--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Students graded at the same time (one per core is about right).")
@click.option("--leaderboard", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write a Markdown table of the students' own agents (lesson 13), "
                   "verified done % first.")
@click.option("--reviews", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None,
              help="The instructor's points for written answers: a CSV with the columns "
                   "student, exercise, points (and comment); <out stem>_reviews.csv is one "
                   "to fill in.")
def course_grade(submissions: Path, out: Path, tests: Path | None, timeout: float,
                 jobs: int, leaderboard: Path | None, reviews: Path | None) -> None:
    """Grade SUBMISSIONS/<student>/ notebook folders; one CSV row of points per student.

    Written answers earn no automatic points: those long enough await the instructor's
    review (their points are pending) until a --reviews file gives them."""
    from dlo_course.grading.grade import grade, leaderboard_markdown
    from dlo_course.grading.notebooks import GRADING_TESTS_DIR

    try:
        rows = grade(submissions, out, tests or GRADING_TESTS_DIR, timeout=timeout, jobs=jobs,
                     reviews=reviews)
    except (ValueError, FileNotFoundError) as err:
        raise click.ClickException(str(err)) from err
    for row in rows:
        note = f"  ({row['error']})" if row["error"] else ""
        waiting = f", {row['pending']:g} awaiting review" if row["pending"] else ""
        click.echo(f"{row['student']}: {row['total']:g} / {row['max_total']:g}{waiting}{note}")
    logs = out.parent / f"{out.stem}_logs"
    feedback = out.parent / f"{out.stem}_feedback"
    to_review = out.parent / f"{out.stem}_reviews.csv"
    click.echo(f"wrote {out} (the grader's output for each student: {logs}; a feedback sheet "
               f"for each student: {feedback}; the written answers to review, to fill in and "
               f"pass back with --reviews: {to_review})")
    if leaderboard is not None:
        leaderboard.parent.mkdir(parents=True, exist_ok=True)
        leaderboard.write_text(leaderboard_markdown(rows), encoding="utf-8")
        click.echo(f"wrote {leaderboard}")


@course_group.command("rubrics")
@click.option("--solutions", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Solution notebooks [the repository's solutions/].")
def course_rubrics(solutions: Path | None) -> None:
    """Print every written answer's points, minimum length and rubric (Markdown)."""
    from dlo_course.grading.notebooks import SOLUTIONS_DIR, rubrics_markdown

    try:
        click.echo(rubrics_markdown(solutions or SOLUTIONS_DIR), nl=False)
    except ValueError as err:
        raise click.ClickException(str(err)) from err


@main.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              default=Path("reports/reproduction"), show_default=True)
@click.option("--agents", "--checkpoints", "checkpoints",
              type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder with nodes2/ nodes4/ nodes6/ trained agents or run directories "
                   "(default: the shipped data/checkpoints; --checkpoints: the old name).")
@click.option("--episodes", type=click.IntRange(min=1), default=None,
              help="Test episodes per setting (default 50, which keeps the default run "
                   "under 45 minutes on 2 cores; the committed report: 100; the paper: 1000).")
@click.option("--max-steps", type=click.IntRange(min=1), default=None,
              help="Actions per test episode (default 30, as in the paper).")
@click.option("--whole-database", type=click.Choice(["with", "all", "none"]), default="none",
              show_default=True,
              help="Which cells also get the harder protocol the paper did not run, goals "
                   "drawn from the whole database: those with reinitialisation (about a "
                   "quarter more time), all, or none.")
@click.option("--train", "retrain", is_flag=True,
              help="Train the three agents with --preset first, instead of using --agents.")
@click.option("--preset", "preset_name", type=PRESET_NAMES,
              default=None, help="Trainer preset for --train. 'smoke' alone runs the whole "
                                 "pipeline in minutes (tiny training, 2 episodes per setting).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--time-mode", type=TIME_MODES, default="code", show_default=True)
@click.option("--controller", "controller_name", type=CONTROLLER_NAMES, default=None,
              help="Also evaluate this classical controller ('jacobian', dlo_course.jacobian) "
                   "on the paper's test goals, the same episodes as the agents': "
                   "table1_<controller>.csv and .md, and a section of the report.")
@click.option("--controller-cells", type=click.Choice(["with", "all"]), default="with",
              show_default=True,
              help="The controller's cells: those with reinitialisation, or all 24.")
@click.option("--nodes", "node_counts", type=NODES, multiple=True,
              help="Only the rows of this node count (repeatable; default: 2, 4 and 6, the "
                   "whole table). Only these agents are needed, or trained with --train.")
def reproduce(out: Path, checkpoints: Path | None, episodes: int | None, max_steps: int | None,
              whole_database: str, retrain: bool, preset_name: str | None, seed: int,
              time_mode: str, controller_name: str | None, controller_cells: str,
              node_counts: tuple[int, ...]) -> None:
    """Regenerate the paper's Table I and Figs. 4-5 beside the published numbers."""
    from dlo_course.evaluation import TrainedAgentError
    from dlo_course.reproduce import DEFAULT_EPISODES, reproduce as run
    from dlo_course.rundir import RunFileError

    smoke = preset_name == "smoke"
    if preset_name is not None and not (retrain or smoke):
        raise click.UsageError("--preset chooses how to retrain: add --train "
                               "(only 'smoke' implies it)")
    if retrain and preset_name is None:
        raise click.UsageError("--train needs --preset " + "|".join(PRESETS))
    if retrain and checkpoints is not None:
        raise click.UsageError("--train trains new agents; drop --agents")
    episodes = episodes or (2 if smoke else DEFAULT_EPISODES)
    max_steps = max_steps or (10 if smoke else 30)
    try:
        report = run(out, checkpoints=checkpoints, episodes=episodes, max_steps=max_steps,
                     seed=seed, train_preset=preset_name if (retrain or smoke) else None,
                     time_mode=time_mode, whole_database=whole_database,
                     controller=controller_name, controller_cells=controller_cells,
                     nodes=node_counts or NODE_COUNTS)
    except (TrainedAgentError, DatabaseError, RunFileError, FileNotFoundError) as err:
        raise click.ClickException(str(err)) from None
    if report is not None:
        click.echo(f"wrote {report} and the tables and figures beside it")


if __name__ == "__main__":
    main()
