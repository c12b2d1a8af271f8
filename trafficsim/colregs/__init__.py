"""COLREGS decision layer: encounter geometry, ship domains and the decision network."""
