"""Plain twin of :func:`song.pipeline.motion.quality.foot_skating_ratio`.

The GMD skating ratio with explicit loops.
"""

from __future__ import annotations

import math

import numpy as np


def foot_skating_reference(joints: np.ndarray, fps: float, toes: tuple[int, int] = (10, 11)) -> float:
    """GMD skating ratio with loops (see :mod:`song.pipeline.motion.quality`)."""
    n = len(joints)
    if n < 2:
        return 0.0
    count = 0
    for f in range(n - 1):
        skating = False
        for toe in toes:
            # a centred 5-frame mean with edge frames repeated ("nearest")
            window = []
            for g in range(f - 2, f + 3):
                gg = min(max(g, 0), n - 2)
                a, b = joints[gg, toe], joints[gg + 1, toe]
                window.append(math.hypot(b[0] - a[0], b[1] - a[1]) * fps)
            now = window[2]
            low = joints[f, toe, 2] < 0.05 and joints[f + 1, toe, 2] < 0.05
            if low and now > 0.5 and sum(window) / 5 > 0.5:
                skating = True
        count += skating
    return count / n
