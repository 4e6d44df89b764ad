"""slam2d.backend."""
