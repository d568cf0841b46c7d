"""Numerics: the LuGre recurrence, least squares, the numpy networks."""
