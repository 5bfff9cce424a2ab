"""Data formats: scene packages (input) and benchmark releases (output)."""
