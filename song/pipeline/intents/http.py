"""An HTTP transport for the LLM SDKs that never holds more than a bounded reply, raw or decoded.

The SDKs' HTTP client (``httpx2``, or ``httpx`` for older SDKs) reads a whole reply and decodes its
``Content-Encoding`` before SONG sees the text, so a 1 MB gzip reply can become gigabytes in memory
before :data:`~song.pipeline.intents.llm.MAX_REPLY_BYTES` is checked. :func:`bounded_transport` reads
the raw body up to a limit, decodes gzip or deflate itself with ``zlib``'s ``max_length`` (never more
than the limit plus one byte), asks only for encodings it can decode this way, and hands the SDK the
decoded body with ``Content-Encoding`` removed. A reply over the limit raises :class:`ReplyTooLarge`,
which the clients turn into a non-retryable :class:`~song.pipeline.intents.llm.LLMError`.
"""

from __future__ import annotations

import zlib
from typing import Any

from song.errors import SongError

ACCEPT_ENCODING = "gzip, deflate"


class ReplyTooLarge(SongError):
    """An LLM server's reply body is over the limit, before or after decoding."""


def http_module() -> Any:
    """The HTTP client module the installed SDKs use (``httpx2``, else ``httpx``)."""
    try:
        import httpx2

        return httpx2
    except ImportError:
        import httpx

        return httpx


def decode_bounded(raw: bytes, encoding: str, max_bytes: int) -> bytes:
    """``raw`` decoded by its ``Content-Encoding`` (identity, gzip or deflate), at most ``max_bytes`` long.

    Raises:
        ReplyTooLarge: the decoded body is over ``max_bytes`` (decoding stops one byte past it).
        SongError: an encoding other than identity, gzip or deflate, or a corrupt stream.
    """
    codings = [c.strip().lower() for c in encoding.split(",") if c.strip() and c.strip().lower() != "identity"]
    body = raw
    for coding in reversed(codings):  # applied in order, so undone in reverse
        if coding in ("gzip", "x-gzip"):
            decoder = zlib.decompressobj(16 + zlib.MAX_WBITS)
        elif coding == "deflate":  # zlib-wrapped as the RFC says, raw deflate as some servers send
            decoder = zlib.decompressobj(zlib.MAX_WBITS if body[:1] == b"\x78" else -zlib.MAX_WBITS)
        else:
            raise SongError(f"LLM reply: unsupported Content-Encoding {coding!r}")
        try:
            body = decoder.decompress(body, max_bytes + 1)
        except zlib.error as exc:
            raise SongError(f"LLM reply: corrupt {coding} body ({exc})") from None
        if len(body) > max_bytes:
            raise ReplyTooLarge(f"LLM reply decodes to over {max_bytes:,} bytes ({coding}); refused")
    return body


def bounded_transport(max_bytes: int) -> Any:
    """An ``HTTPTransport`` whose replies are at most ``max_bytes``, raw and decoded (see the module docstring)."""
    http = http_module()

    class BoundedTransport(http.HTTPTransport):
        def handle_request(self, request):
            request.headers["Accept-Encoding"] = ACCEPT_ENCODING
            response = super().handle_request(request)
            raw = bytearray()
            try:
                for chunk in response.stream:
                    raw += chunk
                    if len(raw) > max_bytes:
                        raise ReplyTooLarge(f"LLM reply is over {max_bytes:,} bytes on the wire; refused")
            finally:
                response.close()
            body = decode_bounded(bytes(raw), response.headers.get("Content-Encoding", ""), max_bytes)
            headers = [
                (name, value)
                for name, value in response.headers.raw
                if name.lower() not in (b"content-encoding", b"content-length", b"transfer-encoding")
            ]
            return http.Response(
                response.status_code, headers=headers, content=body, request=request, extensions=response.extensions
            )

    return BoundedTransport()
