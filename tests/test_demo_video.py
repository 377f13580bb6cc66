"""``dlo-course demo``: watching an agent, a controller or random actions as captioned frames,
a GIF and (with ffmpeg) an MP4. Renders are tiny (64 x 48) and episodes 2 actions long: the
simulator's reset is the cost here, not the pictures."""

from __future__ import annotations

import stat

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from dlo_course import plots
from dlo_course.cli import main
from dlo_course.demo import DEFAULT_GOAL_INDEX, run_demo
from dlo_course.paths import DATA_DIR

pytestmark = pytest.mark.slow  # every test resets the simulator and renders

SHIPPED_AGENT = DATA_DIR / "checkpoints" / "nodes4"
WIDTH, HEIGHT = 64, 48


def captioned_height(height: int = HEIGHT) -> int:
    """Height of a demo frame: the render and the caption band above it (two lines)."""
    return plots.caption_frame(np.zeros((height, WIDTH, 3), np.uint8), ["a", "b"]).shape[0]


def gif_frames(path) -> list[np.ndarray]:
    """Every frame of a GIF, checking on the way that it is one."""
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        frames = []
        for k in range(gif.n_frames):
            gif.seek(k)
            frames.append(np.asarray(gif.convert("RGB")))
    return frames


# --- the pieces, without the simulator ---


def test_caption_frame_puts_a_band_above_the_picture_and_keeps_it():
    frame = np.random.default_rng(0).integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    captioned = plots.caption_frame(frame, ["agent", "mean node distance 0.123 m"])
    band = captioned.shape[0] - HEIGHT
    assert captioned.shape[1:] == (WIDTH, 3) and captioned.dtype == np.uint8
    assert band > 0
    np.testing.assert_array_equal(captioned[band:], frame)  # nothing drawn over the scene
    assert (captioned[:band] < 128).any()  # some text in the band


def test_gif_holds_the_frames_it_is_told_to(tmp_path):
    frames = [np.full((HEIGHT, WIDTH, 3), v, np.uint8) for v in (0, 80, 160, 240)]
    path = plots.save_gif(frames, tmp_path / "x.gif", fps=10, hold=[3], hold_seconds=1.5)
    assert len(gif_frames(path)) == 4
    with Image.open(path) as gif:
        durations = []
        for k in range(gif.n_frames):
            gif.seek(k)
            durations.append(gif.info["duration"])
    assert durations == [100, 100, 100, 1500]


def test_no_mp4_without_an_encoder(tmp_path, monkeypatch):
    monkeypatch.setattr(plots, "video_encoder", lambda: None)
    frames = [np.zeros((HEIGHT, WIDTH, 3), np.uint8)] * 2
    assert plots.save_mp4(frames, tmp_path / "x.mp4") is None
    assert not (tmp_path / "x.mp4").exists()


def test_mp4_pipes_every_frame_to_the_encoder(tmp_path):
    """A stand-in for ffmpeg that stores what it is sent: the raw frames, the held one
    repeated for its seconds."""
    fake = tmp_path / "ffmpeg"
    fake.write_text('#!/bin/sh\nfor last; do :; done\ncat > "$last"\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    frames = [np.full((HEIGHT, WIDTH, 3), v, np.uint8) for v in (0, 100, 200)]
    path = plots.save_mp4(frames, tmp_path / "x.mp4", fps=10, hold=[2], hold_seconds=0.5,
                          encoder=str(fake))
    sent = np.frombuffer(path.read_bytes(), np.uint8).reshape(-1, HEIGHT, WIDTH, 3)
    assert [int(f[0, 0, 0]) for f in sent] == [0, 100] + [200] * 5


def test_agent_and_controller_together_is_a_usage_error():
    result = CliRunner().invoke(main, ["demo", "--agent", str(SHIPPED_AGENT),
                                       "--controller", "jacobian"])
    assert result.exit_code == 2 and "not both" in result.output


# --- with the simulator: tiny renders, 2 actions per episode ---


def test_demo_of_the_shipped_agent_on_two_goals(tmp_path, monkeypatch):
    monkeypatch.setattr(plots, "video_encoder", lambda: None)  # the same run with or without
    out = tmp_path / "demo.png"
    result = CliRunner().invoke(main, [
        "demo", "--agent", str(SHIPPED_AGENT), "--goal-index", str(DEFAULT_GOAL_INDEX),
        "--goal-index", "26", "--steps", "2", "--width", str(WIDTH), "--height",
        str(HEIGHT), "--out", str(out)])
    assert result.exit_code == 0, result.output
    # Both goals start about 0.18 m away: neither episode ends before its 2 actions.
    assert f"goal {DEFAULT_GOAL_INDEX}: 2 actions" in result.output
    assert "goal 26: 2 actions" in result.output
    assert out.is_file() and out.with_suffix(".gif").is_file()
    assert not out.with_suffix(".mp4").exists()
    frames = gif_frames(out.with_suffix(".gif"))
    assert len(frames) == 2 * (1 + 2)  # per episode: the start and one frame per action
    assert all(f.shape == (captioned_height(), WIDTH, 3) for f in frames)
    # The episode moves the robot and rod: consecutive frames differ below the caption.
    band = captioned_height() - HEIGHT
    assert not np.array_equal(frames[0][band:], frames[2][band:])


def test_demo_of_the_jacobian_controller(tmp_path):
    out = tmp_path / "jacobian.png"
    result = CliRunner().invoke(main, ["demo", "--controller", "jacobian", "--steps", "2",
                                       "--width", str(WIDTH), "--height", str(HEIGHT),
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert len(gif_frames(out.with_suffix(".gif"))) == 3


def test_random_demo_with_only_a_width(tmp_path):
    """Random actions, as the demo always did; one side given, the other keeps 4:3."""
    summary = run_demo(steps=2, seed=0, width=WIDTH, mp4=False, out=tmp_path / "random.png")
    assert "2 actions" in summary and "wrote" in summary
    assert (tmp_path / "random.png").is_file()
    frames = gif_frames(tmp_path / "random.gif")
    assert len(frames) == 3 and frames[0].shape == (captioned_height(WIDTH * 3 // 4), WIDTH, 3)


def test_an_out_of_range_goal_is_a_clear_error(tmp_path):
    result = CliRunner().invoke(main, ["demo", "--agent", str(SHIPPED_AGENT), "--goal-index",
                                       "100000", "--steps", "1", "--width", str(WIDTH),
                                       "--out", str(tmp_path / "x.png")])
    assert result.exit_code == 1 and "out of range" in result.output
    assert "Traceback" not in result.output
