"""SONG: social-navigation episode synthesis and benchmark builder.

Layers: ``geometry`` → ``datasets`` → ``pipeline`` / ``runtime`` / ``viz`` → ``cli``.
"""

__version__ = "0.1.0"
