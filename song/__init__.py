"""SONG: social-navigation episode synthesis and benchmark builder.

Layers (DESIGN §2): ``geometry`` → ``datasets`` → ``pipeline`` / ``runtime`` / ``viz`` → ``cli``.
"""

__version__ = "0.1.0"
