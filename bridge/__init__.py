"""The Zenoh bus linking a MAVLink front-seat, back-seat autonomy processes and the MCAP logger.

Never imports :mod:`sim`; the planner wires the autonomy to the bus.
"""
