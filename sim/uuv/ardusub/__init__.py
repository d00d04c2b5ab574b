"""The simulated front-seat that answers as ArduSub does: MAVLink, modes, parameters, streams, missions."""
