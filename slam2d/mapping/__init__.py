"""slam2d.mapping."""
