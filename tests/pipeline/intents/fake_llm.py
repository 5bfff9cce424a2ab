"""Local stand-ins for the LLM services, on 127.0.0.1: Gemini's REST ``generateContent`` and an
OpenAI-compatible ``/chat/completions``. Each request pops the next scripted reply."""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer


class FakeServer:
    """Scripted replies: a list of (status, text, delay_s); ``requests`` records what arrived."""

    def __init__(self, kind: str, script: list[tuple[int, str, float]]) -> None:
        self.kind, self.script, self.requests = kind, list(script), []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server API
                length = int(self.headers.get("Content-Length", 0))
                outer.requests.append(
                    {"path": self.path, "headers": dict(self.headers), "body": json.loads(self.rfile.read(length))}
                )
                status, text, delay = outer.script.pop(0) if outer.script else (500, "", 0.0)
                time.sleep(delay)
                if status == 200:
                    if outer.kind == "gemini":
                        payload = {
                            "candidates": [
                                {"content": {"role": "model", "parts": [{"text": text}]}, "finishReason": "STOP"}
                            ]
                        }
                    else:
                        payload = {"choices": [{"index": 0, "message": {"role": "assistant", "content": text}}]}
                else:
                    payload = {"error": {"code": status, "message": "scripted failure", "status": "UNAVAILABLE"}}
                data = json.dumps(payload).encode()
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", "application/json")
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
