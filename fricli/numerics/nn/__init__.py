"""A small neural-network core in numpy: activations, dense networks, Adam, training loops."""

from fricli.numerics.nn.adam import Adam
from fricli.numerics.nn.network import Network, Workspace
from fricli.numerics.nn.training import Standardizer, Trainer

__all__ = ["Adam", "Network", "Workspace", "Standardizer", "Trainer"]
