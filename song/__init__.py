"""SONG: social-navigation episode synthesis and benchmark builder.

Layers: ``geometry`` → ``datasets`` → ``pipeline`` / ``runtime`` / ``viz`` → ``cli``.
"""

import os as _os

__version__ = "0.1.0"

# numba's parallel kernels run on OpenMP threads here; GNU OpenMP lets idle threads spin, which on a
# shared 2-core machine cost the renderer a third of its frame rate under load, and passive waiting
# nothing measurable without load (benchmarks/threading_layers.py, docs/render.md). libgomp reads this
# when numba first loads it, so it must be set before the first parallel kernel runs; a value the user
# set is kept, as is their NUMBA_THREADING_LAYER.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
