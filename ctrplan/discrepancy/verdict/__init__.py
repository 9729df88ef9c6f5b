"""Stages 4-5 and 7-8 of the discrepancy workflow: the tests and the decision.

- :mod:`.signatures`: each effect's signature test on the held-out residuals;
- :mod:`.statistics`: comparisons of cross-validated models and intervals over units;
- :mod:`.consistency`: is a residual noise; :mod:`.decision`: which effect is named;
- :mod:`.envelope`: the prediction with the motion history; :mod:`.coverage`: how often the
  friction bound covers the test errors.
"""
