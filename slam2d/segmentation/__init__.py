"""slam2d.segmentation."""
