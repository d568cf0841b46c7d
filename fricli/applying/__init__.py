"""Applying models: prediction, evaluation, reports, the EMPS benchmark."""
