"""Local stand-ins for the LLM services on 127.0.0.1 that behave like the real ones where it matters.

- Gemini ``generateContent`` (v1beta REST, what google-genai sends): like the real API it rejects a
  ``responseSchema`` holding a field the OpenAPI-subset schema does not know (the SDK turns pydantic's
  ``extra="forbid"`` into ``additional_properties``, and the real API answers 400 "Unknown name"),
  accepts ``responseJsonSchema`` (full JSON Schema), and sends 429s with a ``RetryInfo`` delay.
- OpenAI-compatible ``/chat/completions``: 429s with ``Retry-After``, redirects, and a server that
  closes the socket after reading the request.

A script is a list of steps ``(status, text, delay_s)``; ``status`` is an HTTP code, ``"close"`` (drop
the connection), ``"redirect"`` (302 to the URL in ``text``) or ``"refuse"`` (a 200 without content, as
the services answer a safety block: Gemini's ``promptFeedback.blockReason`` — or, with ``text`` =
``"candidate"``, a candidate stopped with ``finishReason: SAFETY`` — and OpenAI's ``message.refusal``,
or with ``text`` = ``"content_filter"``, that finish reason), ``"object"`` (the reply's JSON object as the
message content itself, not its text), ``"429-string"`` (a 429 whose ``error`` is a bare string) or
``"drip"`` (a slow-loris reply: one byte every ``delay_s``, each read on time) or ``"gzip-bomb"`` (a
gzip-encoded 200 whose body decodes to ``delay_s`` MB).
``requests`` records what arrived.
"""

from __future__ import annotations

import functools
import json
import threading
import time
import zlib
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

# the fields of Gemini's Schema object (the OpenAPI 3.0 subset that responseSchema accepts)
GEMINI_SCHEMA_FIELDS = {
    "type", "format", "title", "description", "nullable", "enum", "maxItems", "minItems", "properties",
    "required", "minProperties", "maxProperties", "minLength", "maxLength", "pattern", "example", "anyOf",
    "propertyOrdering", "default", "items", "minimum", "maximum",
}  # fmt: skip
RETRY_DELAY_S = 0.2


def unknown_schema_fields(schema: object, where: str = "response_schema") -> list[str]:
    """Paths of fields Gemini's ``Schema`` does not define (the real API rejects the request)."""
    found = []
    if isinstance(schema, dict):
        for key, value in schema.items():
            if key not in GEMINI_SCHEMA_FIELDS:
                found.append(f"{where}.{key}")
            elif key == "properties" and isinstance(value, dict):
                for name, sub in value.items():
                    found += unknown_schema_fields(sub, f"{where}.properties[{name}]")
            elif key == "items" or key == "anyOf":
                for sub in value if isinstance(value, list) else [value]:
                    found += unknown_schema_fields(sub, f"{where}.{key}")
    return found


def _success(kind: str, text: str) -> dict:
    """A successful reply carrying ``text``, as each service sends it."""
    if kind == "gemini":
        return {"candidates": [{"content": {"role": "model", "parts": [{"text": text}]}, "finishReason": "STOP"}]}
    return {"choices": [{"index": 0, "message": {"role": "assistant", "content": text}}]}


@functools.cache
def _gzip_bomb(kind: str, megabytes: int) -> bytes:
    """A gzip stream of a valid success reply whose text is ``megabytes`` MB of spaces (about 1000:1).

    Built once (compressing 256 MB takes seconds on a loaded machine) and before any request arrives,
    so the client's deadline measures the transfer, not the fake's preparation.
    """
    head, tail = json.dumps(_success(kind, "@")).encode().split(b"@")
    packer = zlib.compressobj(9, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    block = b" " * 2**20
    return (
        packer.compress(head)
        + b"".join(packer.compress(block) for _ in range(megabytes))
        + packer.compress(tail)
        + packer.flush()
    )


class FakeServer:
    """Scripted replies (see the module docstring)."""

    def __init__(self, kind: str, script: list[tuple[int | str, str, float]]) -> None:
        self.kind, self.script, self.requests = kind, list(script), []
        for status, _, size in self.script:
            if status == "gzip-bomb":
                _gzip_bomb(kind, int(size))
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server API
                length = int(self.headers.get("Content-Length", 0))
                body = json.loads(self.rfile.read(length))
                outer.requests.append({"path": self.path, "headers": dict(self.headers), "body": body})
                status, text, delay = outer.script.pop(0) if outer.script else (500, "", 0.0)
                if status not in ("drip", "gzip-bomb"):  # a drip's delay is between its bytes; a bomb's is its size
                    time.sleep(delay)
                if status == "close":  # the server goes away mid-request
                    self.close_connection = True
                    self.connection.shutdown(2)
                    return
                if status == "redirect":
                    self._send(302, b"", {"Location": text})
                    return
                if status == "object":  # a server that sends the JSON object itself as the message content
                    payload = {"choices": [{"index": 0, "message": {"role": "assistant", "content": json.loads(text)}}]}
                    self._send(200, json.dumps(payload).encode(), {"Content-Type": "application/json"})
                    return
                if status == "drip":  # a slow-loris server: the reply one byte at a time, each in time
                    self._drip(text, delay)
                    return
                if status == "gzip-bomb":  # a small gzip body that decodes to ``delay`` MB of one JSON reply
                    self._send(
                        200,
                        _gzip_bomb(outer.kind, int(delay)),
                        {"Content-Type": "application/json", "Content-Encoding": "gzip"},
                    )
                    return
                if status == "429-string":  # a rate limit whose error is a bare string
                    self._send(429, json.dumps({"error": text}).encode(), {"Content-Type": "application/json"})
                    return
                if status == "refuse":
                    self._send(200, json.dumps(self._refusal(text)).encode(), {"Content-Type": "application/json"})
                    return
                if outer.kind == "gemini" and status == 200:
                    bad = unknown_schema_fields(body.get("generationConfig", {}).get("responseSchema", {}))
                    if bad:
                        status, text = 400, f'Invalid JSON payload received. Unknown name "{bad[0].split(".")[-1]}"'
                self._reply(status, text)

            def _drip(self, text: str, every_s: float) -> None:
                data = json.dumps(_success(outer.kind, text)).encode()
                try:
                    self.send_response(200)
                    self.send_header("Content-Type", "application/json")
                    self.send_header("Content-Length", str(len(data)))
                    self.end_headers()
                    for i in range(len(data)):
                        self.wfile.write(data[i : i + 1])
                        self.wfile.flush()
                        time.sleep(every_s)
                except (BrokenPipeError, ConnectionResetError):
                    pass

            def _refusal(self, how: str) -> dict:
                if outer.kind == "gemini":
                    if how == "candidate":
                        return {"candidates": [{"finishReason": "SAFETY", "index": 0}]}
                    return {"promptFeedback": {"blockReason": "SAFETY"}}
                if how == "content_filter":
                    message = {"role": "assistant", "content": None}
                    return {"choices": [{"index": 0, "message": message, "finish_reason": "content_filter"}]}
                message = {"role": "assistant", "content": None, "refusal": "I can't help with that request."}
                return {"choices": [{"index": 0, "message": message, "finish_reason": "stop"}]}

            def _reply(self, status: int, text: str) -> None:
                headers = {}
                if status == 200:
                    payload = _success(outer.kind, text)
                else:
                    error = {"code": status, "message": text or "scripted failure", "status": "UNAVAILABLE"}
                    if status == 429:
                        error["status"] = "RESOURCE_EXHAUSTED"
                        error["details"] = [
                            {"@type": "type.googleapis.com/google.rpc.RetryInfo", "retryDelay": f"{RETRY_DELAY_S}s"}
                        ]
                        headers["Retry-After"] = str(RETRY_DELAY_S)
                    if status == 400:
                        error["status"] = "INVALID_ARGUMENT"
                    payload = {"error": error}
                self._send(status, json.dumps(payload).encode(), {"Content-Type": "application/json", **headers})

            def _send(self, status: int, data: bytes, headers: dict[str, str]) -> None:
                try:
                    self.send_response(status)
                    for name, value in headers.items():
                        self.send_header(name, value)
                    self.send_header("Content-Length", str(len(data)))
                    self.end_headers()
                    self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    pass

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_port}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
