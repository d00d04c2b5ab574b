"""The UUV world: mission simulator, back-seat autonomy, scoring and a MAVLink front-seat.

Depends on :mod:`rapt` for shared types only; never imports :mod:`bridge`.
"""
