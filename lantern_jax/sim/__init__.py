"""Batched closed-loop rollout of World states."""
