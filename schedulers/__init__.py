"""Turning planning jobs and experiment grids into Ray work (issue 5)."""
