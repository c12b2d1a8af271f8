"""pygame without a screen.

SDL picks its video and audio drivers when pygame initialises them; setting the ``dummy``
drivers before pygame is imported makes every drawing call work on a server without a display
or a sound card. Only the font module is initialised: surfaces and drawing need nothing else.
"""

from __future__ import annotations

import os
from types import ModuleType

_ENV = {"SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy", "PYGAME_HIDE_SUPPORT_PROMPT": "1"}


def pygame() -> ModuleType:
    """The pygame module, set up for headless drawing (fonts initialised)."""
    os.environ.update(_ENV)
    import pygame as pg

    if not pg.font.get_init():
        pg.font.init()
    return pg
