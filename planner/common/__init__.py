"""What every stage of the range day reads: the plan file, scenarios, telemetry, JSON."""
