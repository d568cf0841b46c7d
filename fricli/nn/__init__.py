"""A small neural-network core in numpy: activations, dense networks, Adam, training loops."""

from fricli.nn.adam import Adam
from fricli.nn.network import Network, Workspace
from fricli.nn.training import Standardizer, Trainer

__all__ = ["Adam", "Network", "Workspace", "Standardizer", "Trainer"]
