"""The configurations' module: torch-free, and the single source of the command line's
choices and help defaults."""

import subprocess
import sys

from click.testing import CliRunner

from dlo_course import config
from dlo_course.cli import main
from dlo_course.task import DEFAULT_N_NODES


def test_importing_the_config_and_the_command_line_imports_neither_torch_nor_pybullet():
    code = ("import sys, dlo_course.config, dlo_course.cli; "
            "heavy = [m for m in ('torch', 'pybullet') if m in sys.modules]; "
            "print(heavy); sys.exit(1 if heavy else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def test_every_preset_has_a_summary():
    assert set(config.PRESET_SUMMARIES) == set(config.PRESETS)


def test_the_command_line_help_reads_its_defaults_from_the_dataclasses():
    help_text = " ".join(CliRunner().invoke(main, ["train", "--help"]).output.split())
    for name, summary in config.PRESET_SUMMARIES.items():
        assert f"{name} ({summary})" in help_text
    assert f"the paper: {config.DDPGConfig().batch_size}]" in help_text
    assert config.paper_default(config.TrainConfig, "env_kwargs") == {"n_nodes": DEFAULT_N_NODES}
    # the presets that trained the first agent keep their 2 nodes
    assert {name: c.env_kwargs["n_nodes"] for name, c in config.PRESETS.items()} == {
        "smoke": 2, "laptop": 2, "paper": 2, "course": 2, "recipe": 4}
