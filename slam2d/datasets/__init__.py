"""Readers and the simulator, all yielding the same Scan stream."""
