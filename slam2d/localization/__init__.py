"""slam2d.localization."""
