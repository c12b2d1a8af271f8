"""Exports: which records become frames (``--every-s``, the last frame, one frame in a time
window), the files written and their names, the writer and its speed per format, and frames
drawn while a run goes (written as it goes, nothing left behind when it fails)."""

import math

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from tests.render.conftest import Ship
from trafficsim.errors import InputError
from trafficsim.render import export
from trafficsim.render.data import load_run
from trafficsim.render.export import (
    Export,
    LiveFrames,
    check_options,
    frame_stride,
    planned_points,
    render_frame,
    render_run,
)
from trafficsim.render.frame import FrameOptions, Renderer
from trafficsim.run import run_scenario
from trafficsim.units import KN

SMALL = FrameOptions(size_px=(160, 120), dpi=48.0, legend=False, panel=False)


def _ships() -> list[Ship]:
    return [Ship("a", 0.0, 0.0, 0.0, speed_kn=10.0), Ship("b", 2000.0, 500.0, 180.0, speed_kn=8.0)]


@pytest.fixture
def drawn(monkeypatch):
    """The record times export draws frames of, and the ``fit_to`` each renderer was given."""
    seen: dict[str, list] = {"times": [], "fit_to": []}

    class Recording(Renderer):
        def __init__(self, data, options, fit_to=None):
            seen["fit_to"].append(fit_to)
            super().__init__(data, options, fit_to)

        def rgb(self, k):
            seen["times"].append(float(self.data.t_s[k]))
            return super().rgb(k)

    monkeypatch.setattr(export, "Renderer", Recording)
    return seen


def _files(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# frame_stride and check_options


@pytest.mark.parametrize("every_s, record_s, stride", [
    (None, 5.0, 1), (5.0, 5.0, 1), (30.0, 5.0, 6), (10.0, 2.5, 4), (0.3, 0.1, 3),
    (0.7, 0.1, 7), (30.0 + 1e-9, 5.0, 6), (5.0 - 1e-12, 5.0, 1)])
def test_the_stride_is_the_number_of_records_between_frames(every_s, record_s, stride):
    assert frame_stride(every_s, record_s) == stride


@pytest.mark.parametrize("every_s", [7.0, 2.5, 30.5, 0.0, -10.0, 4.9])
def test_an_interval_not_a_whole_multiple_of_the_record_period_is_refused(every_s):
    with pytest.raises(InputError, match=r"whole multiple of the run's record period \(5 s\)") \
            as err:
        frame_stride(every_s, 5.0)
    assert err.value.key == "--every-s" and f"got {every_s:g} s" in err.value.message


def test_the_refusal_names_the_flag_given():
    with pytest.raises(InputError) as err:
        frame_stride(12.0, 5.0, key="--frames-every-s")
    assert err.value.key == "--frames-every-s"


@pytest.mark.parametrize("every_s", [math.inf, math.nan])
def test_an_interval_that_is_not_finite_is_refused_as_an_input_error(every_s):
    with pytest.raises(InputError):
        frame_stride(every_s, 5.0)


@pytest.mark.parametrize("fmt, size, fps", [
    ("png", (161, 121), 10.0), ("gif", (161, 121), 100.0), ("mp4", (160, 120), 0.01)])
def test_options_every_writer_can_honour_pass(fmt, size, fps):
    check_options(fmt, FrameOptions(size_px=size), fps)


@pytest.mark.parametrize("fmt, size, fps, key", [
    ("bmp", (160, 120), 10.0, "--format"), ("mp4", (161, 120), 10.0, "--size"),
    ("mp4", (160, 121), 10.0, "--size"), ("gif", (160, 120), 0.0, "--fps"),
    ("gif", (160, 120), -1.0, "--fps"), ("mp4", (160, 120), 100.5, "--fps")])
def test_options_no_writer_can_honour_are_refused_naming_the_flag(fmt, size, fps, key):
    with pytest.raises(InputError) as err:
        check_options(fmt, FrameOptions(size_px=size), fps)
    assert err.value.key == key


def test_render_checks_its_options_before_reading_the_run(tmp_path):
    with pytest.raises(InputError) as err:
        render_run(tmp_path / "no_such_run", tmp_path / "out", "bmp")
    assert err.value.key == "--format"
    assert not (tmp_path / "out").exists()


# render_run


@pytest.mark.parametrize("n_records, every_s, times", [
    (4, None, [0.0, 5.0, 10.0, 15.0]),
    (13, 30.0, [0.0, 30.0, 60.0]),  # the last record (60 s) falls on the interval
    (12, 30.0, [0.0, 30.0]),  # the last record (55 s) does not: no frame of it
    (12, 55.0, [0.0, 55.0]),
])
def test_frames_are_the_records_at_whole_intervals_from_the_start(synthetic_run, tmp_path,
                                                                  drawn, n_records, every_s,
                                                                  times):
    run = synthetic_run(_ships(), n_records)
    done = render_run(run, tmp_path / "png", "png", every_s=every_s, options=SMALL)
    assert drawn["times"] == times
    assert done.frames == len(times)
    assert [p.name for p in done.paths] == [f"frame_{k:05d}.png" for k in range(len(times))]
    assert _files(tmp_path / "png") == [p.name for p in done.paths]


def test_an_interval_longer_than_the_run_is_refused(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 12)  # records 0 .. 55 s
    with pytest.raises(InputError, match=r"at most the run's duration \(55 s\), got 60 s") as err:
        render_run(run, tmp_path / "png", "png", every_s=60.0, options=SMALL)
    assert err.value.key == "--every-s" and not (tmp_path / "png").exists()


def test_png_frames_are_the_pictures_of_their_records(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 7)
    done = render_run(run, tmp_path / "png", "png", every_s=15.0, options=SMALL)
    renderer = Renderer(load_run(run), SMALL)
    for path, k in zip(done.paths, (0, 3, 6), strict=True):
        with Image.open(path) as image:
            np.testing.assert_array_equal(np.asarray(image.convert("RGB")), renderer.array(k))


def test_a_gif_is_named_after_the_run_folder_even_given_as_a_relative_path(
        synthetic_run, tmp_path, monkeypatch):
    run = synthetic_run(_ships(), 3)
    monkeypatch.chdir(run)
    done = render_run(".", tmp_path / "out", "gif", options=SMALL)
    assert done.paths == [tmp_path / "out" / f"{run.name}.gif"] and done.frames == 3
    assert _files(tmp_path / "out") == [f"{run.name}.gif"]


def test_a_name_given_names_the_gif(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 3)
    done = render_run(run, tmp_path / "out", "gif", options=SMALL, name="encounter_7")
    assert done.paths == [tmp_path / "out" / "encounter_7.gif"]
    assert iio.imread(done.paths[0], index=None).shape == (3, 120, 160, 3)


@pytest.mark.parametrize("fps, delay_ms", [(4.0, 250), (3.0, 330), (0.5, 2000), (100.0, 10)])
def test_the_gif_plays_at_the_fps_asked(synthetic_run, tmp_path, fps, delay_ms):
    run = synthetic_run(_ships(), 2)
    done = render_run(run, tmp_path, "gif", options=SMALL, fps=fps)
    with Image.open(done.paths[0]) as image:
        assert image.info["duration"] == delay_ms


def test_an_mp4_is_named_after_the_run_and_plays_at_the_fps_asked(synthetic_run, tmp_path):
    import imageio_ffmpeg

    run = synthetic_run(_ships(), 6)
    done = render_run(run, tmp_path / "video", "mp4", every_s=10.0, options=SMALL, fps=8.0)
    assert done.paths == [tmp_path / "video" / f"{run.name}.mp4"] and done.frames == 3
    reader = imageio_ffmpeg.read_frames(str(done.paths[0]))
    meta = next(reader)
    assert meta["fps"] == pytest.approx(8.0) and tuple(meta["size"]) == (160, 120)
    assert sum(1 for _ in reader) == 3


@pytest.mark.parametrize("fmt", ["gif", "mp4"])
def test_a_failed_export_leaves_no_file_behind(synthetic_run, tmp_path, monkeypatch, fmt):
    run = synthetic_run(_ships(), 6)
    calls = []

    def failing_rgb(self, k):
        calls.append(k)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return Renderer.rgb(self, k)

    class Failing(Renderer):
        rgb = failing_rgb

    monkeypatch.setattr(export, "Renderer", Failing)
    with pytest.raises(KeyboardInterrupt):
        render_run(run, tmp_path / "out", fmt, options=SMALL)
    assert calls == [0, 1, 2] and _files(tmp_path / "out") == []


@pytest.mark.parametrize("frames, seconds, rate", [(10, 2.0, 5.0), (3, 0.0, math.inf)])
def test_frames_per_second_of_an_export(frames, seconds, rate):
    assert Export([], frames, seconds).frames_per_s == rate


# render_frame


@pytest.mark.parametrize("t_s, shown", [(12.0, 10.0), (13.0, 15.0), (12.5, 10.0),
                                        (-100.0, 0.0), (1e5, 45.0), (30.0, 30.0)])
def test_one_frame_shows_the_record_nearest_the_time(synthetic_run, tmp_path, drawn, t_s,
                                                     shown):
    run = synthetic_run(_ships(), 10)
    path = render_frame(run, tmp_path / "one.png", t_s, SMALL)
    assert path == tmp_path / "one.png" and drawn["times"] == [shown]
    assert drawn["fit_to"] == [None]


def test_one_frame_is_the_picture_of_that_record(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 10)
    render_frame(run, tmp_path / "one.png", 21.0, SMALL)
    with Image.open(tmp_path / "one.png") as image:
        picture = np.asarray(image.convert("RGB"))
    renderer = Renderer(load_run(run), SMALL)
    np.testing.assert_array_equal(picture, renderer.array(4))
    assert not np.array_equal(picture, renderer.array(5))


def test_a_window_fits_the_view_to_the_positions_within_it(synthetic_run, tmp_path, drawn):
    run = synthetic_run(_ships(), 10)
    render_frame(run, tmp_path / "close.png", 21.0, SMALL, window_s=5.0)
    assert drawn["times"] == [20.0]
    north, east = drawn["fit_to"][0]
    # records at 15, 20 and 25 s; a sails north at 10 kn, b south at 8 kn from (2000, 500)
    t = np.array([15.0, 20.0, 25.0])
    expect_north = np.concatenate([10.0 * KN * t, 2000.0 - 8.0 * KN * t])
    expect_east = np.concatenate([np.zeros(3), np.full(3, 500.0)])
    np.testing.assert_allclose(np.sort(np.ravel(north)), np.sort(expect_north), atol=1e-6)
    np.testing.assert_allclose(np.sort(np.ravel(east)), np.sort(expect_east), atol=1e-6)


def test_a_close_up_differs_from_the_whole_run(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 40)
    render_frame(run, tmp_path / "all.png", 100.0, SMALL)
    render_frame(run, tmp_path / "close.png", 100.0, SMALL, window_s=10.0)
    with Image.open(tmp_path / "all.png") as a, Image.open(tmp_path / "close.png") as b:
        assert not np.array_equal(np.asarray(a), np.asarray(b))


# frames drawn while a run goes


def test_planned_points_are_starts_waypoints_and_where_route_less_ships_end(tiny_scenario,
                                                                           tmp_path):
    seen = []

    def hook(rec, sim):
        if not seen:
            seen.append(planned_points(sim, 100.0))

    run_scenario(tiny_scenario(100.0), tmp_path / "out", hook)
    north, east = seen[0]
    points = sorted(zip(np.round(north, 6).tolist(), np.round(east, 6).tolist(), strict=True))
    # own starts at (-3000, 0) with a waypoint at (6000, 0); other starts at (0, 3000) and
    # has no route: 100 s west at 12 kn
    other_end = 3000.0 - 12.0 * KN * 100.0
    expect = sorted([(-3000.0, 0.0), (6000.0, 0.0), (0.0, 3000.0), (0.0, other_end)])
    np.testing.assert_allclose(points, expect, atol=1e-6)


def test_live_frames_take_the_scenario_record_period_and_open_nothing_before_a_record(
        tiny_scenario, tmp_path):
    live = LiveFrames(tiny_scenario(100.0), tmp_path / "frames", "gif", every_s=25.0,
                      options=SMALL)
    assert (live.record_every_s, live.stride, live.name, live.duration_s) == (5.0, 5, "tiny",
                                                                             100.0)
    assert live.close() == [] and live.frames == 0
    live.abort()
    assert not (tmp_path / "frames").exists()


@pytest.mark.parametrize("kw, key", [
    ({"options": FrameOptions(size_px=(160, 120), follow="nobody")}, "--follow"),
    ({"every_s": 12.0}, "--frames-every-s"),
    ({"fmt": "tiff"}, "--format"),
    ({"fmt": "mp4", "options": FrameOptions(size_px=(161, 120))}, "--size"),
])
def test_live_frames_refuse_bad_options_when_built(tiny_scenario, tmp_path, kw, key):
    with pytest.raises(InputError) as err:
        LiveFrames(tiny_scenario(100.0), tmp_path / "frames", **kw)
    assert err.value.key == key
    assert not (tmp_path / "frames").exists()


def test_live_png_frames_are_written_while_the_run_goes(tiny_scenario, tmp_path):
    live = LiveFrames(tiny_scenario(100.0), tmp_path / "frames", "png", every_s=25.0,
                      options=SMALL)
    times, on_disk = [], []

    def hook(rec, sim):
        before = live.frames
        live(rec, sim)
        if live.frames > before:
            times.append(float(rec.t[rec.count - 1]))
            on_disk.append(_files(tmp_path / "frames"))

    run_scenario(tiny_scenario(100.0), tmp_path / "out", hook)
    assert times == [0.0, 25.0, 50.0, 75.0, 100.0]
    # each frame is on disk as soon as its record is drawn
    assert on_disk == [[f"frame_{j:05d}.png" for j in range(k + 1)] for k in range(5)]
    paths = live.close()
    assert live.frames == 5 and paths == [tmp_path / "frames" / f"frame_{k:05d}.png"
                                          for k in range(5)]
    with Image.open(paths[-1]) as image:
        assert image.size == (160, 120)


def test_a_live_gif_appears_under_its_name_only_when_closed(tiny_scenario, tmp_path):
    live = LiveFrames(tiny_scenario(100.0), tmp_path / "frames", "gif", every_s=50.0,
                      options=SMALL, fps=4.0)
    during = []

    def hook(rec, sim):
        live(rec, sim)
        during.append(_files(tmp_path / "frames"))

    run_scenario(tiny_scenario(100.0), tmp_path / "out", hook)
    assert all(len(names) == 1 and names[0].startswith(".tiny.") and names[0].endswith(".gif")
               for names in during)
    assert live.close() == [tmp_path / "frames" / "tiny.gif"]
    assert _files(tmp_path / "frames") == ["tiny.gif"]
    assert iio.imread(tmp_path / "frames" / "tiny.gif", index=None).shape == (3, 120, 160, 3)
    with Image.open(tmp_path / "frames" / "tiny.gif") as image:
        assert image.info["duration"] == 250


def test_a_failed_run_aborted_leaves_no_live_gif_behind(tiny_scenario, tmp_path):
    live = LiveFrames(tiny_scenario(100.0), tmp_path / "frames", "gif", every_s=10.0,
                      options=SMALL)

    def hook(rec, sim):
        live(rec, sim)
        if live.frames == 3:
            raise RuntimeError("the run fails")

    with pytest.raises(RuntimeError, match="the run fails"):
        run_scenario(tiny_scenario(100.0), tmp_path / "out", hook)
    assert len(_files(tmp_path / "frames")) == 1  # the unfinished GIF, under a temporary name
    live.abort()
    assert _files(tmp_path / "frames") == []


@pytest.mark.parametrize("fmt, size, fps, every_s", [
    ("jpeg", (160, 120), 10.0, None), ("mp4", (161, 121), 10.0, None),
    ("gif", (160, 120), 1000.0, None), ("gif", (160, 120), math.nan, None),
    ("png", (160, 120), 10.0, 12.0), ("png", (160, 120), 10.0, -5.0)])
def test_bad_options_are_one_line_input_errors_before_any_file(synthetic_run, tmp_path, fmt,
                                                               size, fps, every_s):
    """Each refusal is an InputError whose text is one line starting with the flag, and the
    output folder is not even created."""
    run = synthetic_run(_ships(), 4)
    with pytest.raises(InputError) as err:
        render_run(run, tmp_path / "out", fmt, every_s=every_s,
                   options=FrameOptions(size_px=size), fps=fps)
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{err.value.key}: ")
    assert err.value.key in ("--format", "--size", "--fps", "--every-s")
    assert not (tmp_path / "out").exists()


def test_an_unknown_ship_to_follow_is_refused_before_any_file(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 4)
    with pytest.raises(InputError) as err:
        render_run(run, tmp_path / "out", "gif",
                   options=FrameOptions(size_px=(160, 120), follow="zz"))
    assert err.value.key == "--follow" and "\n" not in str(err.value)
    assert "'zz'" in err.value.message and "a, b" in err.value.message
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("n_records, record_s, every_s", [
    (10, 2.5, 7.5), (11, 2.5, 7.5), (9, 0.1, 0.3), (1, 5.0, 5.0), (25, 5.0, None)])
def test_frame_count_and_times_of_every_s(synthetic_run, tmp_path, drawn, n_records,
                                          record_s, every_s):
    """Frames at 0, every_s, 2 every_s ... up to the last record: ceil(n_records / stride)
    frames with stride = every_s / record period (7.5 / 2.5 = 3: 10 records give 4 frames,
    times 0, 7.5, 15, 22.5)."""
    run = synthetic_run(_ships(), n_records, every_s=record_s)
    done = render_run(run, tmp_path / "png", "png", every_s=every_s, options=SMALL)
    stride = 1 if every_s is None else round(every_s / record_s)
    count = -(-n_records // stride)
    step = record_s if every_s is None else every_s
    assert done.frames == count == len(done.paths)
    np.testing.assert_allclose(drawn["times"], step * np.arange(count), atol=1e-9)


def test_a_gif_export_lasts_frames_over_fps(synthetic_run, tmp_path):
    """Twelve records every 5 s, a frame every 10 s: six frames at 4 fps, 250 ms each,
    1.5 s in all, each 160 x 120."""
    run = synthetic_run(_ships(), 12)
    done = render_run(run, tmp_path, "gif", every_s=10.0, options=SMALL, fps=4.0)
    with Image.open(done.paths[0]) as image:
        assert image.n_frames == 6 == done.frames and image.size == (160, 120)
        total = 0
        for k in range(6):
            image.seek(k)
            total += image.info["duration"]
    assert total == 1500
