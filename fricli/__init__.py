"""fricli: friction models for robot joints."""

__version__ = "0.1.0"
