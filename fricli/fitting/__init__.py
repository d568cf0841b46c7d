"""Fitting: identification, training, adaptation, diagnosis, the job runner."""
