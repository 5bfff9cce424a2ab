"""Stand-in for Kimodo's compiled motion_correction extension (present: the build succeeded)."""
