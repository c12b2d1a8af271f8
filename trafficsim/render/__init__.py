"""Pictures of runs and campaigns, drawn headless with pygame.

* :mod:`.headless`: pygame without a screen (``SDL_VIDEODRIVER=dummy`` set before import);
* :mod:`.view`: metres north/east to pixels, a view that fits every ship or follows one;
* :mod:`.style`: colours, line widths and font sizes at a DPI; the fixed GIF palette;
* :mod:`.data`: what a frame shows, read from a run folder or taken from a running simulation;
* :mod:`.decisions`: the decision each ship holds at a time and the rule node behind it;
* :mod:`.layers`: one drawing function per layer (routes, tracks, domains, CPA, hulls, ...);
* :mod:`.frame`: :class:`~.frame.Renderer`, which keeps the static layers and draws frames;
* :mod:`.writers`: PNG frames, animated GIF and MP4, each streamed frame by frame to disk;
* :mod:`.export`: ``trafficsim render`` and ``trafficsim run --frames``;
* :mod:`.report`: ``trafficsim report``, one HTML page for a campaign.

pygame, Pillow and imageio are imported inside the functions that need them, so importing
this package (and ``trafficsim --help``) stays fast.
"""
