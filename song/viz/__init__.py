"""Top-down pictures and videos of scenes, crowds, episodes and benchmark statistics."""
