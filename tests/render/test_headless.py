"""pygame without a display: SDL's dummy drivers and no greeting, set before pygame is imported
(checked in a fresh interpreter with a server's environment), fonts ready, and calling again
changes nothing."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from trafficsim.render import headless

ROOT = Path(__file__).resolve().parents[2]
HEADLESS = {"SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy",
            "PYGAME_HIDE_SUPPORT_PROMPT": "1"}


@pytest.fixture
def unset(monkeypatch):
    """The three variables unset, as on a server; whatever they were comes back after the
    test (setenv first so that monkeypatch restores them even when they were absent)."""
    for key in HEADLESS:
        monkeypatch.setenv(key, "")
        monkeypatch.delenv(key)
    return monkeypatch


def _ours() -> dict:
    return {key: os.environ.get(key) for key in HEADLESS}


def test_sets_the_dummy_drivers_and_hides_the_greeting(unset):
    assert _ours() == dict.fromkeys(HEADLESS)
    headless.pygame()
    assert _ours() == HEADLESS


def test_replaces_drivers_set_for_a_desktop(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "x11")
    monkeypatch.setenv("SDL_AUDIODRIVER", "pulseaudio")
    monkeypatch.setenv("PYGAME_HIDE_SUPPORT_PROMPT", "0")
    headless.pygame()
    assert _ours() == HEADLESS


def test_leaves_other_variables_alone(unset):
    unset.setenv("SDL_VIDEO_CENTERED", "1")
    unset.delenv("DISPLAY", raising=False)
    before = {k: v for k, v in os.environ.items() if k not in HEADLESS}
    headless.pygame()
    assert {k: v for k, v in os.environ.items() if k not in HEADLESS} == before


def test_returns_the_pygame_module_with_fonts_ready(unset):
    pg = headless.pygame()
    assert pg is sys.modules["pygame"] and pg.__name__ == "pygame"
    assert pg.font.get_init()
    assert pg.font.Font(None, 24).get_linesize() > 0


def test_a_second_call_changes_nothing(unset):
    pg = headless.pygame()
    font = pg.font.Font(None, 24)
    environ = dict(os.environ)
    assert headless.pygame() is pg
    assert dict(os.environ) == environ
    assert pg.font.get_init()
    assert font.get_linesize() > 0  # a font made before the second call still works


_FRESH = textwrap.dedent("""
    import builtins, json, os, sys

    KEYS = ("SDL_VIDEODRIVER", "SDL_AUDIODRIVER", "PYGAME_HIDE_SUPPORT_PROMPT")
    seen = []
    real_import = builtins.__import__

    def spy(name, *args, **kwargs):
        # the environment as pygame finds it when first imported
        if name == "pygame" and "pygame" not in sys.modules:
            seen.append({k: os.environ.get(k) for k in KEYS})
        return real_import(name, *args, **kwargs)

    builtins.__import__ = spy
    before = {k: os.environ.get(k) for k in KEYS}
    from trafficsim.render import headless
    early = "pygame" in sys.modules
    pg = headless.pygame()
    fonts = pg.font.get_init()
    others = [pg.display.get_init(), pg.mixer.get_init() is not None]
    surf = pg.Surface((8, 8))  # drawing needs nothing more
    pg.draw.line(surf, (255, 0, 0), (0, 3), (7, 3))
    pg.font.quit()
    again = headless.pygame() is pg and pg.font.get_init()
    pg.display.init()
    pg.display.set_mode((8, 8))
    pg.mixer.init()
    print(json.dumps({"before": before, "at_import": seen, "early": early, "fonts": fonts,
                      "others": others, "again": again, "video": pg.display.get_driver(),
                      "audio": pg.mixer.get_init() is not None,
                      "drawn": list(surf.get_at((5, 3)))[:3]}))
""")


def test_in_a_fresh_interpreter_on_a_server_pygame_starts_headless():
    """No display, no sound device, no SDL settings: the drivers work, and were set before
    pygame was imported (seen by a hook on imports)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY") and not k.startswith(("SDL_", "PYGAME"))}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    res = subprocess.run([sys.executable, "-c", _FRESH], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=60)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert len(lines) == 1, lines  # our line only: no greeting
    assert "Hello from the pygame community" not in res.stdout + res.stderr
    out = json.loads(lines[0])
    assert out["before"] == dict.fromkeys(HEADLESS)
    assert not out["early"]  # importing the module does not start pygame
    assert out["at_import"] == [HEADLESS]  # set before pygame was imported
    assert out["fonts"] and out["again"]  # fonts initialised, and again after a quit
    assert out["others"] == [False, False]  # only the fonts
    assert out["video"] == "dummy" and out["audio"]
    assert out["drawn"] == [255, 0, 0]
