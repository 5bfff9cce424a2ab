"""Video files: H.264 MP4 through PyAV (figures, first-person views, collected datasets)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from song.util import atomic_writer


def write_mp4(path: str | Path, frames: Iterable[np.ndarray], fps: float) -> Path:
    """Write RGB frames as an H.264 MP4 (yuv420p, what browsers play) through PyAV, atomically.

    Dimensions are cropped to even numbers for the codec. The same frames give the same bytes: x264
    runs single-threaded and without its macroblock-tree rate control (``mbtree=0``), whose results
    varied from one encode of the same frames to the next in the FFmpeg that PyAV bundles (measured:
    up to 7 different files in 8 encodes of one episode with it, 1 without).
    """
    from fractions import Fraction

    import av

    path = Path(path)
    with atomic_writer(path) as handle, av.open(handle, "w", format="mp4") as container:
        stream = None
        for frame in frames:
            if stream is None:
                h, w = frame.shape[0] - frame.shape[0] % 2, frame.shape[1] - frame.shape[1] % 2
                stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
                stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
                stream.options = {"crf": "20", "preset": "medium", "threads": "1", "x264-params": "mbtree=0"}
            video = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame[:h, :w]), format="rgb24")
            container.mux(stream.encode(video))
        if stream is None:
            raise ValueError(f"{path}: no frames to write")
        container.mux(stream.encode(None))
    return path
