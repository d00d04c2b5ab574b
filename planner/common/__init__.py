"""What every stage of the range day reads: the plan file and its schema, scenario resolution,
the vehicle's telemetry, a scenario's GeoJSON, the ``meta/scenario`` record, the HTML kit, JSON."""
