"""Diagnosis: which physical effect is a friction model missing on a log?

    effects.py    the library of candidate effects (groups of ``fricli.models.terms``, physical parameters)
    selection.py  blocked cross-validation over time, significance, forward selection
    driver.py     the driver: residual -> ranked effects (``diagnose``)
    fix.py        the result -> the augmented model (``augment``), carried by a LuGre base where natural
"""

from fricli.fitting.diagnosis.driver import Diagnosis, EffectResult, diagnose

__all__ = ["Diagnosis", "EffectResult", "diagnose"]
