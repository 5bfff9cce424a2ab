"""LLM clients for intents: Gemini (google-genai SDK) and any OpenAI-compatible server.

Both speak one protocol, :class:`LLMClient` (``provider``, ``model``, ``request(prompt, schema)``
returning the raw reply text). :func:`structured_call` adds what every provider needs: a disk cache
keyed by (provider, model, prompt sha256, schema version) so re-runs make no calls, bounded retries
with exponential back-off and jitter on 408/429/5xx, time-outs and dropped connections (a 429's
suggested delay honoured), one repair attempt when a reply is not valid JSON for the schema, and a
process-wide concurrency limit. API keys never reach a file, a log line or an error message: replies
(before they are parsed or cached) and messages are scrubbed of every key value in the environment.
"""

from __future__ import annotations

import json
import os
import random
import threading
import time
from pathlib import Path
from typing import Protocol, TypeVar

from pydantic import BaseModel, ValidationError

from song.errors import MissingDependencyError, SongError
from song.pipeline.intents.http import bounded_transport
from song.pipeline.intents.schemas import SCHEMA_VERSION
from song.util import sha256_bytes, sha256_json, write_text_atomic

KEY_VARIABLES = ("GOOGLE_API_KEY", "GEMINI_API_KEY", "OPENAI_API_KEY")
RETRY_STATUS = {408, 429, 500, 502, 503, 504}
MAX_RETRY_AFTER_S = 60.0  # a server's suggested retry delay is honoured up to this
MAX_REPLY_BYTES = 256 * 1024  # a scene description or a dozen routines is a few KB; larger replies are refused
MAX_HTTP_BYTES = 4 * MAX_REPLY_BYTES  # the whole HTTP body (the reply JSON-escaped inside its envelope), raw or decoded
T = TypeVar("T", bound=BaseModel)
_SLOTS: dict[int, threading.BoundedSemaphore] = {}


class LLMError(SongError):
    """The LLM could not produce a valid answer (after retries and one repair)."""


class LLMRefusal(LLMError):
    """The service refused or blocked the request (a safety block, a refusal, a content filter).

    Recorded as such; never repaired or retried (the same prompt would be refused again).
    """


class TransientLLMError(LLMError):
    """A failure worth retrying: 408/429/5xx, a time-out, a refused or dropped connection.

    ``retry_after_s`` is the server's suggested delay (a 429's ``Retry-After`` or Gemini's
    ``RetryInfo``), when it gave one.
    """

    def __init__(self, message: str, retry_after_s: float | None = None) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s


def scrub(text: str) -> str:
    """Remove every API key value found in the environment from ``text``."""
    for name in KEY_VARIABLES:
        value = os.environ.get(name)
        if value:
            text = text.replace(value, "***")
    return text


def scrub_reply(text: str) -> str:
    """:func:`scrub` a JSON reply, and its decoded strings too.

    A key written with JSON escapes (a letter as a ``u0041`` escape) survives a text scrub; it is caught
    in the decoded strings and the reply re-encoded. Text that is not JSON is scrubbed as text.
    """
    text = scrub(text)
    try:
        data = json.loads(text)
    except ValueError:
        return text

    def clean(value):
        if isinstance(value, str):
            return scrub(value)
        if isinstance(value, list):
            return [clean(v) for v in value]
        if isinstance(value, dict):
            return {scrub(str(k)): clean(v) for k, v in value.items()}
        return value

    cleaned = clean(data)
    return text if cleaned == data else json.dumps(cleaned, ensure_ascii=False)


def _seconds(value: object) -> float | None:
    """``"1.5"``, ``"20s"`` or a number → seconds; None when absent or unreadable."""
    try:
        return max(0.0, float(str(value).strip().removesuffix("s")))
    except (TypeError, ValueError):
        return None


class LLMClient(Protocol):
    """A provider client: one structured request at a time."""

    provider: str
    model: str

    def request(self, prompt: str, schema: type[BaseModel]) -> str:
        """Send one prompt asking for JSON that fits ``schema``; returns the raw reply text."""
        ...


def _gemini_retry_delay(details: object) -> float | None:
    for item in details if isinstance(details, list) else []:
        if isinstance(item, dict) and str(item.get("@type", "")).endswith("google.rpc.RetryInfo"):
            return _seconds(item.get("retryDelay"))
    return None


class GeminiClient:
    """Gemini through the official ``google-genai`` SDK with structured JSON output.

    The JSON schema goes in ``response_json_schema`` (sent as ``responseJsonSchema``, full JSON Schema):
    passing the pydantic model as ``response_schema`` makes the SDK send ``additional_properties``
    inside the OpenAPI-subset ``responseSchema``, which the Gemini API rejects with 400 (a known
    python-genai behaviour, googleapis/python-genai#1815). The key comes from ``GOOGLE_API_KEY`` / ``GEMINI_API_KEY`` with the SDK's own
    precedence (SONG never handles the value). ``base_url`` points the SDK elsewhere (tests).
    """

    provider = "gemini"

    def __init__(self, model: str, timeout_s: float, base_url: str | None = None) -> None:
        try:
            from google import genai
            from google.genai import types
        except ImportError as exc:
            raise MissingDependencyError("google-genai", "gemini") from exc
        self.model = model
        self.timeout_s = float(timeout_s)  # the whole request's deadline (the HTTP timeout is per read)
        self._types = types
        options = types.HttpOptions(
            timeout=int(timeout_s * 1000),
            client_args={  # the key header never goes to another origin; the reply is bounded as it is read
                "follow_redirects": False,
                "transport": bounded_transport(MAX_HTTP_BYTES),
            },
            **({"base_url": base_url} if base_url else {}),
        )
        try:
            self._client = genai.Client(http_options=options)
        except Exception as exc:  # no key, bad options
            raise LLMError(scrub(f"gemini client: {exc}")) from exc

    def request(self, prompt: str, schema: type[BaseModel]) -> str:
        """One structured Gemini call; returns the reply text (errors raise :class:`LLMError`)."""
        from google.genai import errors

        config = self._types.GenerateContentConfig(
            response_mime_type="application/json", response_json_schema=schema.model_json_schema()
        )
        try:
            response = self._client.models.generate_content(model=self.model, contents=prompt, config=config)
        except errors.APIError as exc:
            if 300 <= (exc.code or 0) < 400:
                raise LLMError(
                    f"gemini answered with a redirect (HTTP {exc.code}); redirects are not followed"
                ) from None
            if exc.code in RETRY_STATUS:
                error = exc.details.get("error") if isinstance(exc.details, dict) else None
                delay = _gemini_retry_delay(error.get("details") if isinstance(error, dict) else None)
                raise TransientLLMError(scrub(f"gemini HTTP {exc.code}: {exc.message}"), delay) from None
            raise LLMError(scrub(f"gemini HTTP {exc.code}: {exc.message}")) from None
        except SongError as exc:  # the bounded transport refused the body
            raise LLMError(scrub(str(exc))) from None
        except Exception as exc:  # time-outs, refused or dropped connections (httpx errors): all transient
            raise TransientLLMError(scrub(f"gemini request failed: {type(exc).__name__}: {exc}")) from None
        text = response.text
        if not text:
            _gemini_refusal(response)
        return text or ""


def _name(value: object) -> str:
    return str(getattr(value, "name", value))


def _gemini_refusal(response: object) -> None:
    """Raise :class:`LLMRefusal` for an empty Gemini reply that says why (blocked prompt, stopped reply)."""
    feedback = getattr(response, "prompt_feedback", None)
    block = getattr(feedback, "block_reason", None)
    if block:
        detail = getattr(feedback, "block_reason_message", None)
        raise LLMRefusal(scrub(f"gemini blocked the prompt: {_name(block)}" + (f" ({detail})" if detail else "")))
    candidates = getattr(response, "candidates", None) or []
    reason = _name(getattr(candidates[0], "finish_reason", "")) if candidates else ""
    if reason and reason not in ("STOP", "FINISH_REASON_UNSPECIFIED"):
        raise LLMRefusal(f"gemini stopped the reply without content: finish reason {reason}")


class OpenAICompatibleClient:
    """Any server speaking the OpenAI chat-completions API (vLLM, Ollama, llama.cpp), through the ``openai`` SDK.

    JSON-schema output (``response_format``), the SDK's own retries off (:func:`structured_call`
    retries), and redirects not followed: the ``Authorization`` header never goes to another origin.
    ``OPENAI_API_KEY`` is sent when set (local servers usually ignore it).
    """

    provider = "openai"

    def __init__(self, base_url: str, model: str, timeout_s: float) -> None:
        try:
            import openai
        except ImportError as exc:
            raise MissingDependencyError("openai", "openai") from exc
        self._openai = openai
        self.base_url = base_url.rstrip("/")
        self.model = model
        self.timeout_s = float(timeout_s)  # the whole request's deadline (the HTTP timeout is per read)
        self._client = openai.OpenAI(
            base_url=self.base_url,
            api_key=os.environ.get("OPENAI_API_KEY") or "no-key",  # the SDK insists on one; servers may not
            timeout=timeout_s,
            max_retries=0,
            http_client=openai.DefaultHttpxClient(follow_redirects=False, transport=bounded_transport(MAX_HTTP_BYTES)),
        )

    def request(self, prompt: str, schema: type[BaseModel]) -> str:
        """One chat-completions call with JSON-schema output; returns the reply text (errors: :class:`LLMError`)."""
        openai = self._openai
        response_format = {
            "type": "json_schema",
            "json_schema": {"name": schema.__name__, "schema": schema.model_json_schema(), "strict": True},
        }
        try:
            reply = self._client.chat.completions.create(
                model=self.model, messages=[{"role": "user", "content": prompt}], response_format=response_format
            )
        except openai.APIStatusError as exc:
            code = exc.status_code
            if 300 <= code < 400:
                target = exc.response.headers.get("location", "?")
                raise LLMError(
                    scrub(
                        f"openai-compatible server at {self.base_url} redirected to {target}; redirects are not followed"
                    )
                ) from None
            if code in RETRY_STATUS:
                headers = exc.response.headers
                delay = _seconds(headers.get("retry-after"))
                raise TransientLLMError(scrub(f"openai-compatible HTTP {code}"), delay) from None
            raise LLMError(scrub(f"openai-compatible HTTP {code}")) from None
        except openai.APITimeoutError:
            raise TransientLLMError(f"openai-compatible time-out after {self._client.timeout} s") from None
        except openai.APIConnectionError as exc:  # refused, reset or closed connections
            raise TransientLLMError(scrub(f"openai-compatible connection failed: {exc.__cause__ or exc}")) from None
        except openai.OpenAIError as exc:
            raise LLMError(scrub(f"openai-compatible request failed: {type(exc).__name__}: {exc}")) from None
        except SongError as exc:  # the bounded transport refused the body
            raise LLMError(scrub(str(exc))) from None
        try:
            choice = reply.choices[0]
            message = choice.message
        except (AttributeError, IndexError, TypeError) as exc:
            raise LLMError(f"openai-compatible reply has no message content: {exc}") from None
        refusal = getattr(message, "refusal", None)
        if refusal:
            raise LLMRefusal(scrub(f"openai-compatible model refused: {refusal}"))
        if not message.content and getattr(choice, "finish_reason", None) == "content_filter":
            raise LLMRefusal("openai-compatible reply withheld by the server's content filter")
        content = message.content
        if isinstance(content, (dict, list)):  # a server that sends the JSON object itself, not its text
            return json.dumps(content)
        if content is not None and not isinstance(content, str):
            raise LLMError(f"openai-compatible reply content is a {type(content).__name__}, not text")
        return content or ""


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
    if cached is not None and cached.is_file() and cached.stat().st_size <= MAX_REPLY_BYTES:
        try:
            return _parse(cached.read_text(encoding="utf-8"), schema)
        except ValidationError:
            pass  # a stale or damaged cache entry: ask again
    rng = rng or random.Random(0)
    text = scrub_reply(_with_retries(client, prompt, schema, max_retries, backoff_s, max_concurrency, rng))
    try:
        result = _parse(text, schema)
    except ValidationError as exc:
        repair = (
            f"{prompt}\n\nYour previous reply was not valid JSON for the required schema "
            f"({exc.error_count()} problems, first: {exc.errors()[0]['msg']}). Reply again with only valid JSON."
        )
        text = scrub_reply(_with_retries(client, repair, schema, max_retries, backoff_s, max_concurrency, rng))
        try:
            result = _parse(text, schema)
        except ValidationError as again:
            raise LLMError(
                f"{client.provider} reply still invalid after one repair: {again.errors()[0]['msg']}"
            ) from None
    if cached is not None:
        write_text_atomic(cached, text)
    return result


def _bounded(client, text: str) -> str:
    """The reply, unless it is over ``MAX_REPLY_BYTES`` (then an :class:`LLMError`: the offline model stands in)."""
    size = len(text.encode("utf-8", errors="replace"))
    if size > MAX_REPLY_BYTES:
        raise LLMError(f"{client.provider} reply is {size:,} bytes, over the {MAX_REPLY_BYTES:,}-byte limit")
    return text


def _within_deadline(client, prompt: str, schema) -> str:
    """``client.request`` with a deadline on the whole request (``client.timeout_s``, when it has one).

    HTTP clients time out per read, so a server that sends a byte now and then holds a request for as
    long as it likes; here the request runs in a daemon thread that is abandoned at the deadline.
    """
    deadline = getattr(client, "timeout_s", None)
    if not deadline:
        return client.request(prompt, schema)
    box: dict = {}

    def call() -> None:
        try:
            box["reply"] = client.request(prompt, schema)
        except BaseException as exc:  # handed to the caller's thread
            box["error"] = exc

    worker = threading.Thread(target=call, daemon=True)
    worker.start()
    worker.join(deadline)
    if worker.is_alive():
        raise TransientLLMError(f"{client.provider} request timed out: no complete reply within {deadline:g} s")
    if "error" in box:
        raise box["error"]
    return box["reply"]


def _with_retries(client, prompt, schema, max_retries, backoff_s, max_concurrency, rng) -> str:
    for attempt in range(max_retries):
        try:
            with _slot(max_concurrency):
                return _bounded(client, _within_deadline(client, prompt, schema))
        except TransientLLMError as exc:
            delay = backoff_s * (2**attempt) * (0.5 + rng.random())  # exponential back-off with jitter
            if exc.retry_after_s is not None:  # the server said when to come back
                delay = max(delay, min(exc.retry_after_s, MAX_RETRY_AFTER_S))
            time.sleep(delay)
    with _slot(max_concurrency):
        return _bounded(client, _within_deadline(client, prompt, schema))  # the last try: its error goes up
