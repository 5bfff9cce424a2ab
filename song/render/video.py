"""Video files: H.264 MP4 through PyAV (figures, first-person views, collected datasets)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from song.util import atomic_writer


class Mp4Writer:
    """An H.264 MP4 (yuv420p, what browsers play) written frame by frame through PyAV, atomically.

    Dimensions are cropped to even numbers for the codec. The same frames give the same bytes: x264
    runs single-threaded and without its macroblock-tree rate control (``mbtree=0``), whose results
    varied from one encode of the same frames to the next in the FFmpeg that PyAV bundles (measured:
    up to 7 different files in 8 encodes of one episode with it, 1 without). ``frames`` counts what
    was written and ``size_bytes`` how large the file has grown, so a caller can start a new file
    at a size limit (LeRobot's shared video files).
    """

    def __init__(self, path: str | Path, fps: float) -> None:
        import av

        self.path, self.fps, self.frames = Path(path), fps, 0
        self._stack = contextlib.ExitStack()
        self._handle = self._stack.enter_context(atomic_writer(self.path))
        self._container = self._stack.enter_context(av.open(self._handle, "w", format="mp4"))
        self._stream = None

    def write(self, frames: Iterable[np.ndarray]) -> None:
        """Append RGB frames (H, W, 3) uint8."""
        from fractions import Fraction

        import av

        for frame in frames:
            if self._stream is None:
                self._size = frame.shape[0] - frame.shape[0] % 2, frame.shape[1] - frame.shape[1] % 2
                stream = self._container.add_stream("libx264", rate=Fraction(self.fps).limit_denominator(1000))
                stream.height, stream.width = self._size
                stream.pix_fmt = "yuv420p"
                stream.options = {"crf": "20", "preset": "medium", "threads": "1", "x264-params": "mbtree=0"}
                self._stream = stream
            h, w = self._size
            video = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame[:h, :w]), format="rgb24")
            self._container.mux(self._stream.encode(video))
            self.frames += 1

    @property
    def size_bytes(self) -> int:
        """Bytes written to the file so far."""
        return self._handle.tell()

    def __enter__(self) -> Mp4Writer:
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is None:
            self.close()
        else:
            self._stack.__exit__(kind, error, trace)  # the temporary file is removed, the path untouched

    def close(self) -> Path:
        """Flush the encoder and move the file into place (a file without frames is an error)."""
        try:
            if self._stream is None:
                raise ValueError(f"{self.path}: no frames to write")
            self._container.mux(self._stream.encode(None))
        except BaseException as error:
            self._stack.__exit__(type(error), error, error.__traceback__)
            raise
        self._stack.close()
        return self.path


def write_mp4(path: str | Path, frames: Iterable[np.ndarray], fps: float) -> Path:
    """Write RGB frames as one H.264 MP4 (:class:`Mp4Writer`), atomically."""
    with Mp4Writer(path, fps) as writer:
        writer.write(frames)
    return Path(path)
