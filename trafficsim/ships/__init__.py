"""Ship models, the ship library and standard manoeuvres."""
