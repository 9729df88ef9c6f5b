"""Stages 3 and 6 of the discrepancy workflow: the models along the motion and their fits.

- :mod:`.simulate`: the models along a motion (branch following; the friction state comes from
  :mod:`ctrplan.history`; Sections III and V-B of Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019,
  doi:10.1109/TRO.2018.2878906);
- :mod:`.parameters`: calibration parameters (baseline tube parameters and effect parameters);
- :mod:`.predictions`: a model's tip poses at the data's samples and their Eq. (49) errors;
- :mod:`.calibrate`: least squares on Eq. (49); :mod:`.gridsearch`: the grid search of friction
  coefficients; :mod:`.fitoptions`: where a fit starts and how it runs; :mod:`.estimates`:
  standard errors and parameter tables;
- :mod:`.evaluation`: out-of-fold errors; :mod:`.baseline`: the baseline calibration (stage 3);
- :mod:`.fitting`: cross-validated fits and the candidate effects (stage 6), each by its fit
  strategy (:class:`ctrplan.effects.FitStrategy`); :mod:`.pairs`: a second effect fitted with
  the named one.
"""
