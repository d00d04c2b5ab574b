"""Imitation-learning surrogates of the back-seat autonomy (chapter 6).

The features and actions of section 6.5.3 (:mod:`sim.uuv.imitation.features`), a learned
policy driving vehicles in place of the expert (:mod:`sim.uuv.imitation.driver`), rollouts
that record the expert's commands while the policy flies (:mod:`sim.uuv.imitation.rollouts`)
and trained surrogates as files tied to their mission (:mod:`sim.uuv.imitation.surrogate`).
The learners themselves know nothing of vehicles: :mod:`rapt.imitation`.
"""
