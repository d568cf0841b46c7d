"""fricli: friction models for robot joints."""

__version__ = "0.2.0"
