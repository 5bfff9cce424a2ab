"""LLM clients for intents: Gemini (google-genai SDK) and any OpenAI-compatible server (DESIGN §5.1).

Both speak one protocol, :class:`LLMClient` (``provider``, ``model``, ``request(prompt, schema)``
returning the raw reply text). :func:`structured_call` adds what every provider needs: a disk cache
keyed by (provider, model, prompt sha256, schema version) so re-runs make no calls, bounded retries
with exponential back-off and jitter on 408/429/5xx and time-outs, one repair attempt when a reply is
not valid JSON for the schema, and a process-wide concurrency limit. API keys never reach a file, a
log line or an error message: messages are scrubbed of every key value in the environment.
"""

from __future__ import annotations

import json
import os
import random
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Protocol, TypeVar

from pydantic import BaseModel, ValidationError

from song.errors import MissingDependencyError, SongError
from song.pipeline.intents.schemas import SCHEMA_VERSION
from song.util import sha256_bytes, sha256_json, write_text_atomic

KEY_VARIABLES = ("GOOGLE_API_KEY", "GEMINI_API_KEY", "OPENAI_API_KEY")
RETRY_STATUS = {408, 429, 500, 502, 503, 504}
T = TypeVar("T", bound=BaseModel)
_SLOTS: dict[int, threading.BoundedSemaphore] = {}


class LLMError(SongError):
    """The LLM could not produce a valid answer (after retries and one repair)."""


class TransientLLMError(LLMError):
    """A failure worth retrying: 408/429/5xx or a time-out."""


def scrub(text: str) -> str:
    """Remove every API key value found in the environment from ``text``."""
    for name in KEY_VARIABLES:
        value = os.environ.get(name)
        if value:
            text = text.replace(value, "***")
    return text


class LLMClient(Protocol):
    """A provider client: one structured request at a time."""

    provider: str
    model: str

    def request(self, prompt: str, schema: type[BaseModel]) -> str:
        """Send one prompt asking for JSON that fits ``schema``; returns the raw reply text."""
        ...


class GeminiClient:
    """Gemini through the official ``google-genai`` SDK with structured JSON output.

    The key comes from ``GOOGLE_API_KEY`` / ``GEMINI_API_KEY`` with the SDK's own precedence (the SDK
    reads them; SONG never handles the value). ``base_url`` points the SDK elsewhere (tests).
    """

    provider = "gemini"

    def __init__(self, model: str, timeout_s: float, base_url: str | None = None) -> None:
        try:
            from google import genai
            from google.genai import types
        except ImportError as exc:
            raise MissingDependencyError("google-genai", "gemini") from exc
        self.model = model
        self._types = types
        options = (
            types.HttpOptions(timeout=int(timeout_s * 1000), base_url=base_url)
            if base_url
            else types.HttpOptions(timeout=int(timeout_s * 1000))
        )
        try:
            self._client = genai.Client(http_options=options)
        except Exception as exc:  # no key, bad options
            raise LLMError(scrub(f"gemini client: {exc}")) from exc

    def request(self, prompt: str, schema: type[BaseModel]) -> str:
        """One structured Gemini call; returns the reply text (errors raise :class:`LLMError`)."""
        from google.genai import errors

        config = self._types.GenerateContentConfig(response_mime_type="application/json", response_schema=schema)
        try:
            response = self._client.models.generate_content(model=self.model, contents=prompt, config=config)
        except errors.APIError as exc:
            kind = TransientLLMError if exc.code in RETRY_STATUS else LLMError
            raise kind(scrub(f"gemini HTTP {exc.code}: {exc.message}")) from None
        except Exception as exc:  # httpx time-outs and connection errors
            if "timeout" in type(exc).__name__.lower() or "timed out" in str(exc).lower():
                raise TransientLLMError(scrub(f"gemini time-out: {exc}")) from None
            raise LLMError(scrub(f"gemini request failed: {type(exc).__name__}: {exc}")) from None
        return response.text or ""


class OpenAICompatibleClient:
    """Any server speaking the OpenAI chat-completions API with JSON-schema output (vLLM, Ollama, llama.cpp)."""

    provider = "openai"

    def __init__(self, base_url: str, model: str, timeout_s: float) -> None:
        self.base_url = base_url.rstrip("/")
        self.model = model
        self.timeout_s = timeout_s

    def request(self, prompt: str, schema: type[BaseModel]) -> str:
        """One chat-completions call in JSON mode; returns the reply text (errors raise :class:`LLMError`)."""
        body = {
            "model": self.model,
            "messages": [{"role": "user", "content": prompt}],
            "response_format": {
                "type": "json_schema",
                "json_schema": {"name": schema.__name__, "schema": schema.model_json_schema(), "strict": True},
            },
        }
        headers = {"Content-Type": "application/json"}
        if os.environ.get("OPENAI_API_KEY"):
            headers["Authorization"] = f"Bearer {os.environ['OPENAI_API_KEY']}"
        req = urllib.request.Request(f"{self.base_url}/chat/completions", json.dumps(body).encode(), headers)
        try:
            with urllib.request.urlopen(req, timeout=self.timeout_s) as reply:
                data = json.loads(reply.read())
        except urllib.error.HTTPError as exc:
            kind = TransientLLMError if exc.code in RETRY_STATUS else LLMError
            raise kind(scrub(f"openai-compatible HTTP {exc.code}")) from None
        except (TimeoutError, urllib.error.URLError) as exc:
            if isinstance(exc, TimeoutError) or "timed out" in str(exc):
                raise TransientLLMError(scrub(f"openai-compatible time-out: {exc}")) from None
            raise LLMError(scrub(f"openai-compatible request failed: {exc}")) from None
        except ValueError as exc:
            raise LLMError(f"openai-compatible reply is not JSON: {exc}") from None
        try:
            return data["choices"][0]["message"]["content"]
        except (KeyError, IndexError, TypeError) as exc:
            raise LLMError(f"openai-compatible reply has no message content: {exc}") from None


def _slot(limit: int) -> threading.BoundedSemaphore:
    return _SLOTS.setdefault(limit, threading.BoundedSemaphore(limit))


def _parse(text: str, schema: type[T]) -> T:
    return schema.model_validate_json(text)


def structured_call(
    client: LLMClient,
    prompt: str,
    schema: type[T],
    cache_dir: Path | None,
    max_retries: int = 4,
    backoff_s: float = 1.0,
    max_concurrency: int = 4,
    rng: random.Random | None = None,
) -> T:
    """Ask ``client`` for a reply matching ``schema`` (cached, retried, repaired once)."""
    key = sha256_json(
        {
            "provider": client.provider,
            "model": client.model,
            "prompt": sha256_bytes(prompt.encode()),
            "schema": SCHEMA_VERSION,
        }
    )
    cached = cache_dir / f"{key}.json" if cache_dir is not None else None
    if cached is not None and cached.is_file():
        try:
            return _parse(cached.read_text(encoding="utf-8"), schema)
        except ValidationError:
            pass  # a stale or damaged cache entry: ask again
    rng = rng or random.Random(0)
    text = _with_retries(client, prompt, schema, max_retries, backoff_s, max_concurrency, rng)
    try:
        result = _parse(text, schema)
    except ValidationError as exc:
        repair = (
            f"{prompt}\n\nYour previous reply was not valid JSON for the required schema "
            f"({exc.error_count()} problems, first: {exc.errors()[0]['msg']}). Reply again with only valid JSON."
        )
        text = _with_retries(client, repair, schema, max_retries, backoff_s, max_concurrency, rng)
        try:
            result = _parse(text, schema)
        except ValidationError as again:
            raise LLMError(
                f"{client.provider} reply still invalid after one repair: {again.errors()[0]['msg']}"
            ) from None
    if cached is not None:
        write_text_atomic(cached, text)
    return result


def _with_retries(client, prompt, schema, max_retries, backoff_s, max_concurrency, rng) -> str:
    for attempt in range(max_retries):
        try:
            with _slot(max_concurrency):
                return client.request(prompt, schema)
        except TransientLLMError:
            time.sleep(backoff_s * (2**attempt) * (0.5 + rng.random()))  # exponential back-off with jitter
    with _slot(max_concurrency):
        return client.request(prompt, schema)  # the last try: its error goes to the caller
