"""slam2d.planning."""
