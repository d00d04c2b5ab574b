"""The simulated systems RAPT tests, one sub-package each.

- :mod:`sim.uuv` — the UUV world: vectorized mission simulator, back-seat autonomy,
  scoring and a MAVLink front-seat (chapters 3, 4 and 6 of the dissertation).
- :mod:`sim.robots` — the self-righting ground robots (chapter 5).

The two share nothing but :mod:`rapt`'s types and never import each other; neither
imports :mod:`bridge` or :mod:`planner`.
"""
