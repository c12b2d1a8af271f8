"""Sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks.

:mod:`~trafficsim.diagnose.data` cuts measured runs into replay windows with their measured
channels and manoeuvre phases, :mod:`~trafficsim.diagnose.fit` fits the candidate effects of
:mod:`trafficsim.effects` and ranks them on held-out data, :mod:`~trafficsim.diagnose.selftest`
checks the chain on simulated runs with a hidden effect, :mod:`~trafficsim.diagnose.mmgfolder`
reads an MMG parameter folder as a base ship, :mod:`~trafficsim.diagnose.report` writes the
reports and :mod:`~trafficsim.diagnose.command` is ``trafficsim diagnose``.
"""
