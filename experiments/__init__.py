"""The studies of drill-string-gym, the top floor: the ``drill-gym`` command line, the
controller comparison on the paper's scenarios (``compare``), the stick-slip maps (``map``),
the held-out evaluation of trained agents (``evaluate``), their figures and tables.

Studies use only the public interface of the floors below: ``gym.make``/``gym.make_vec``,
:func:`drill_env.evaluation.rollout` and the controller registry.
"""
