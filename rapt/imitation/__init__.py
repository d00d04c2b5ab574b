"""Imitation learning of a black-box expert (section 6.4), one concept per module.

* :mod:`~rapt.imitation.dagger` - the loop: behavioural cloning, DAgger and Q-DAgger
  (:func:`~rapt.imitation.dagger.imitate`), and the runs a ``rollout`` returns;
* :mod:`~rapt.imitation.policies` - the trained networks as exact numpy policies
  (:class:`~rapt.imitation.policies.MLPPolicy`, :class:`~rapt.imitation.policies.HeadsPolicy`),
  and how they are saved;
* :mod:`~rapt.imitation.decisions` - switch columns learned as classifiers and sharpened
  at the end;
* :mod:`~rapt.imitation.queries` - where to ask the expert next: the learner's boundary
  candidates and where its updates disagree.
"""
