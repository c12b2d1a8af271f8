"""``trafficsim render`` and ``trafficsim run --frames`` as a user meets them: on a machine
without a display, errors in one line with exit code 2."""

import os
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import pytest
from PIL import Image

from tests.render.conftest import Ship
from trafficsim.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _headless_env() -> dict[str, str]:
    """The environment of a server: no display, no SDL settings, this worktree first."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY") and not k.startswith(("SDL_", "PYGAME"))}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return env


def test_a_run_becomes_a_gif_while_it_goes_then_an_mp4_without_a_display(tiny_scenario,
                                                                          tmp_path):
    out = tmp_path / "run"
    res = subprocess.run([sys.executable, "-m", "trafficsim", "run", tiny_scenario(), "--out",
                          out, "--frames", "gif", "--frames-every-s", "50", "--size", "320x240"],
                         capture_output=True, text=True, env=_headless_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    assert "pygame" not in res.stdout + res.stderr  # no greeting
    gif = out / "frames" / "tiny.gif"
    assert f"frames: 9 (gif) in {gif}" in res.stdout
    assert iio.imread(gif, index=None).shape == (9, 240, 320, 3)
    res = subprocess.run([sys.executable, "-m", "trafficsim", "render", out, "--format", "mp4",
                          "--every-s", "20", "--size", "320x240", "--follow", "own",
                          "--measurements", "--out", tmp_path / "video", "--no-progress"],
                         capture_output=True, text=True, env=_headless_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    video = tmp_path / "video" / "run.mp4"
    assert res.stdout.startswith("21 frames in ") and str(video) in res.stdout
    assert video.stat().st_size > 1000


def test_render_writes_png_frames_at_the_interval(synthetic_run, tmp_path, capsys):
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0, speed_kn=10.0), Ship("b", 2000.0, 0.0, 180.0,
                                                                         speed_kn=10.0)], 13)
    code = main(["render", str(run), "--every-s", "30", "--size", "200x150", "--dpi", "48",
                 "--out", str(tmp_path / "png"), "--no-progress"])
    assert code == 0
    assert capsys.readouterr().out.startswith("3 frames in ")
    frames = sorted((tmp_path / "png").glob("*.png"))
    assert [f.name for f in frames] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    with Image.open(frames[0]) as image:
        assert image.size == (200, 150)


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


@pytest.mark.parametrize("args, expect", [
    (["--every-s", "7"], "--every-s: expected a whole multiple of the run's record period (5 s)"),
    (["--format", "mp4", "--size", "321x240"], "--size: MP4 frames need an even width"),
    (["--follow", "nobody"], "--follow: no ship 'nobody' in this run; ships: a"),
    (["--fps", "500", "--format", "gif"], "--fps: expected 0.01 <= fps <= 100"),
])
def test_render_option_errors_are_one_line(synthetic_run, tmp_path, capsys, args, expect):
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 4)
    code = main(["render", str(run), "--out", str(tmp_path / "o"), *args])
    assert code == 2 and expect in _one_line(capsys)


@pytest.mark.parametrize("args, expect", [
    (["--format", "bmp"], "invalid choice: 'bmp'"),
    (["--size", "huge"], "expected WIDTHxHEIGHT"),
    (["--size", "20x20"], "expected 64 to 8192 pixels"),
    (["--every-s", "-5"], "expected a positive number"),
])
def test_render_flag_errors_are_one_line(tmp_path, capsys, args, expect):
    with pytest.raises(SystemExit) as stop:
        main(["render", str(tmp_path), "--out", str(tmp_path / "o"), *args])
    assert stop.value.code == 2 and expect in _one_line(capsys)


def test_render_names_a_folder_that_is_not_a_run(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert f"{tmp_path / 'nope'}: no such folder" in _one_line(capsys)
    assert main(["render", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "no trajectories.parquet here" in _one_line(capsys)


def test_run_frames_checks_its_interval_before_running(tiny_scenario, tmp_path, capsys):
    code = main(["run", str(tiny_scenario()), "--out", str(tmp_path / "o"), "--frames", "png",
                 "--frames-every-s", "12"])
    assert code == 2 and "--frames-every-s: expected a whole multiple" in _one_line(capsys)
    code = main(["run", str(tiny_scenario()), "--out", str(tmp_path / "o"), "--frames",
                 "--follow", "nobody"])
    assert code == 2 and "--follow: no ship 'nobody' in " in _one_line(capsys)
    assert not (tmp_path / "o").exists()
