"""Driving policies: the interface, the registry and the reference planners."""
