"""slam2d.evaluation."""
