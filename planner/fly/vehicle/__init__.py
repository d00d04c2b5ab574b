"""A run on a vehicle's MAVLink port and its guards: bring-up, watchdog, referee, virtual range."""
