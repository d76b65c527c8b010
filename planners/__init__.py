"""Pure planning algorithms for SteelPath.

Every module here takes numpy arrays, networkx graphs and dataclasses and
returns the same; nothing here touches the network, files or global state.
Errors are :mod:`planners.errors` exceptions (``ValueError`` subclasses).
"""
