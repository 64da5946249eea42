"""Geometry: SE(2) algebra, the camera model, and the ground geometry that turns image motion into body motion."""
