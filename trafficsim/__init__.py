"""trafficsim: fast-time multi-ship traffic and collision-avoidance simulator."""

__version__ = "0.1.0"
