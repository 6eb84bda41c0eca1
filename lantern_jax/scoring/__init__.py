"""Cooperative Unified Score: telemetry accumulators, components, gates, CUS, aggregation."""
