"""The SIL flight: the simulated front-seat, bridge, back-seat and logger wired on loopback, checked against the batch."""
