"""Ship control: heading autopilot, speed by engine order, route guidance."""
