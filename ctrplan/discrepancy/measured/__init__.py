"""Stage 1-2 of the discrepancy workflow: the measured data and how they are split.

- :mod:`.data`: measured data with its whole recorded motion and configuration groups;
- :mod:`.split`: the development / test split and the cross-validation folds with their buffers;
- :mod:`.noise`: the sensor noise from rests and its correlation;
- :mod:`.synth`: measured-like data with hidden effects of :mod:`ctrplan.effects` and sensor noise
  (``ctrplan synth``).
"""
