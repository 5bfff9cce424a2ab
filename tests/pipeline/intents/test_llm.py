"""LLM paths against local fake servers (no test touches the internet): the real google-genai SDK
against a fake ``generateContent``, and the OpenAI-compatible client against a fake chat endpoint."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from song.config import SongConfig
from song.datasets.scenes import load_scene_package
from song.pipeline.intents import generate_intents
from tests.pipeline.intents.fake_llm import FakeServer

KEY = "test-key-SECRET-1234567890"
DESC = json.dumps({"description": "An office: desk_1 in room_a, sofa_1 in room_b, printer_1 near the door."})


@pytest.fixture(autouse=True)
def _confined(nothing_written_outside) -> None:
    """Every case here must leave everything outside its own tmp_path as it was."""


def routines(*pairs: tuple[str, str]) -> str:
    return json.dumps(
        {"routines": [{"start_object": a, "goal_object": b, "activity": f"walks from {a} to {b}"} for a, b in pairs]}
    )


GOOD = routines(("desk_1", "sofa_1"), ("printer_1", "sofa_1"))


def _run(make_scene, tmp_path: Path, monkeypatch, kind: str, script, **intents_cfg):
    pytest.importorskip("google.genai")
    server = FakeServer(kind, script)
    try:
        if kind == "gemini":
            monkeypatch.setenv("GOOGLE_API_KEY", KEY)
            monkeypatch.setenv("SONG_GEMINI_BASE_URL", server.url)
            cfg = {"llm": "auto", **intents_cfg}
        else:
            monkeypatch.setenv("OPENAI_API_KEY", KEY)
            cfg = {"llm": "openai", "openai_base_url": server.url + "/v1", "openai_model": "qwen-local", **intents_cfg}
        config = SongConfig(intents={"backoff_base_s": 0.01, "timeout_s": 2.0, **cfg})
        package = load_scene_package(make_scene())
        result = generate_intents(package, config, np.random.default_rng(0), cache_dir=tmp_path / "cache")
        return result, server
    finally:
        server.close()


def _no_key_anywhere(tmp_path: Path, result) -> None:
    assert KEY not in result.model_dump_json()
    for path in tmp_path.rglob("*"):
        if path.is_file():
            assert KEY.encode() not in path.read_bytes(), path


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_success_uses_structured_output_and_caches(make_scene, tmp_path, monkeypatch, kind) -> None:
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [(200, DESC, 0), (200, GOOD, 0)])
    assert result.provenance.provider == kind and not result.provenance.fallback
    assert len(result.provenance.prompt_sha256) == 64
    assert {(i.start_object, i.goal_object) for i in result.intents} <= {("desk_1", "sofa_1"), ("printer_1", "sofa_1")}
    assert result.intents and result.description.startswith("An office")
    first = server.requests[0]
    if kind == "gemini":
        assert (
            ":generateContent" in first["path"]
            and first["body"]["generationConfig"]["responseMimeType"] == "application/json"
        )
        assert (
            "responseSchema" in first["body"]["generationConfig"]
            or "responseJsonSchema" in first["body"]["generationConfig"]
        )
    else:
        assert first["path"] == "/v1/chat/completions" and first["body"]["response_format"]["type"] == "json_schema"
    _no_key_anywhere(tmp_path, result)
    again, server2 = _run(make_scene, tmp_path, monkeypatch, kind, [])  # cached: no request at all
    assert server2.requests == [] and again.model_dump_json() == result.model_dump_json()


def test_a_reply_naming_only_unknown_objects_falls_back(make_scene, tmp_path, monkeypatch) -> None:
    reply = routines(("ghost_9", "sofa_1"), ("desk_1", "nowhere_2"))
    result, _ = _run(make_scene, tmp_path, monkeypatch, "openai", [(200, DESC, 0), (200, reply, 0)])
    assert result.provenance.fallback and result.intents  # the offline model stood in
    assert "none of the model's 2 routines passed the filters (unknown_object 2)" in result.llm_error
    assert len(result.provenance.prompt_sha256) == 64  # which prompts were sent is recorded even so


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_429_then_success(make_scene, tmp_path, monkeypatch, kind) -> None:
    result, server = _run(
        make_scene, tmp_path, monkeypatch, kind, [(429, "", 0), (200, DESC, 0), (503, "", 0), (200, GOOD, 0)]
    )
    assert not result.provenance.fallback and len(server.requests) == 4


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_persistent_500_falls_back_and_records(make_scene, tmp_path, monkeypatch, kind) -> None:
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [(500, "", 0)] * 10, max_retries=2)
    assert result.provenance.fallback and result.provenance.provider == kind
    assert "500" in result.llm_error and result.intents  # the offline model stood in
    assert len(server.requests) == 3
    _no_key_anywhere(tmp_path, result)


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_an_oversized_reply_is_refused_and_falls_back(make_scene, tmp_path, monkeypatch, kind) -> None:
    from song.pipeline.intents.llm import MAX_REPLY_BYTES

    huge = json.dumps({"description": "x" * (MAX_REPLY_BYTES + 10)})
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [(200, huge, 0)] * 3)
    assert result.provenance.fallback and result.intents  # the offline model stood in
    assert "over the 262,144-byte limit" in result.llm_error
    assert len(server.requests) == 1  # a refused size is not retried


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_malformed_json_is_repaired(make_scene, tmp_path, monkeypatch, kind) -> None:
    result, server = _run(
        make_scene, tmp_path, monkeypatch, kind, [(200, "{not json", 0), (200, DESC, 0), (200, GOOD, 0)]
    )
    assert not result.provenance.fallback and "not valid JSON" in server.requests[1]["body"].__repr__()


def test_unknown_object_ids_are_rejected_with_reasons(make_scene, tmp_path, monkeypatch) -> None:
    reply = routines(("desk_1", "sofa_1"), ("ghost_9", "sofa_1"), ("desk_1", "nowhere_2"))
    result, _ = _run(make_scene, tmp_path, monkeypatch, "gemini", [(200, DESC, 0), (200, reply, 0)])
    reasons = {(r.start_object, r.goal_object): r.reason for r in result.rejected}
    assert reasons[("ghost_9", "sofa_1")] == "unknown_object" and reasons[("desk_1", "nowhere_2")] == "unknown_object"
    assert [(i.start_object, i.goal_object) for i in result.intents] == [("desk_1", "sofa_1")]


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_slow_reply_times_out_then_falls_back(make_scene, tmp_path, monkeypatch, kind) -> None:
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [(200, DESC, 3.0)] * 3, max_retries=1, timeout_s=0.5)
    assert result.provenance.fallback and result.intents
    assert "time" in result.llm_error.lower()


def test_gemini_gets_a_json_schema_the_api_accepts(make_scene, tmp_path, monkeypatch) -> None:
    """The real API rejects `additional_properties` inside responseSchema; the fake does too."""
    result, server = _run(make_scene, tmp_path, monkeypatch, "gemini", [(200, DESC, 0), (200, GOOD, 0)])
    config = server.requests[0]["body"]["generationConfig"]
    assert "responseJsonSchema" in config and "responseSchema" not in config
    assert config["responseJsonSchema"]["additionalProperties"] is False
    assert not result.provenance.fallback


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_dropped_connection_is_retried(make_scene, tmp_path, monkeypatch, kind) -> None:
    result, server = _run(
        make_scene, tmp_path, monkeypatch, kind, [("close", "", 0), (200, DESC, 0), ("close", "", 0), (200, GOOD, 0)]
    )
    assert not result.provenance.fallback and len(server.requests) == 4


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_a_429_suggested_delay_is_honoured(make_scene, tmp_path, monkeypatch, kind) -> None:
    import time

    from tests.pipeline.intents.fake_llm import RETRY_DELAY_S

    start = time.perf_counter()
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [(429, "", 0), (200, DESC, 0), (200, GOOD, 0)])
    assert not result.provenance.fallback and len(server.requests) == 3
    assert time.perf_counter() - start >= RETRY_DELAY_S  # the back-off alone would be ~0.01 s


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_a_redirect_never_carries_the_key_elsewhere(make_scene, tmp_path, monkeypatch, kind) -> None:
    elsewhere = FakeServer(kind, [(200, DESC, 0)] * 4)
    try:
        script = [("redirect", elsewhere.url + "/v1/chat/completions", 0)] * 4
        result, _ = _run(make_scene, tmp_path, monkeypatch, kind, script, max_retries=1)
    finally:
        elsewhere.close()
    assert elsewhere.requests == []  # not followed at all
    assert result.provenance.fallback and "redirect" in result.llm_error
    _no_key_anywhere(tmp_path, result)


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_an_echoed_key_is_stored_nowhere(make_scene, tmp_path, monkeypatch, kind) -> None:
    echo = json.dumps({"description": f"An office. Authorization: Bearer {KEY}"})
    result, _ = _run(make_scene, tmp_path, monkeypatch, kind, [(200, echo, 0), (200, GOOD, 0)])
    assert not result.provenance.fallback and "***" in result.description
    _no_key_anywhere(tmp_path, result)


@pytest.mark.parametrize(
    ("kind", "how", "said"),
    [
        ("gemini", "", "gemini blocked the prompt: SAFETY"),
        ("gemini", "candidate", "finish reason SAFETY"),
        ("openai", "", "model refused: I can't help"),
        ("openai", "content_filter", "content filter"),
    ],
)
def test_a_safety_block_is_recorded_as_such_without_a_repair(make_scene, tmp_path, monkeypatch, kind, how, said):
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [("refuse", how, 0)] + [(200, GOOD, 0)] * 3)
    assert result.provenance.fallback and said in result.llm_error, result.llm_error
    assert "Invalid JSON" not in result.llm_error
    assert len(server.requests) == 1  # no repair request, no retry: the same prompt would be refused again


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_a_key_written_with_json_escapes_is_stored_nowhere(make_scene, tmp_path, monkeypatch, kind) -> None:
    escaped = f"\\u{ord(KEY[0]):04x}" + KEY[1:]  # the key's first letter as a JSON escape
    echo = '{"description": "An office. The key is ' + escaped + '"}'
    result, _ = _run(make_scene, tmp_path, monkeypatch, kind, [(200, echo, 0), (200, GOOD, 0)])
    assert not result.provenance.fallback and "***" in result.description
    _no_key_anywhere(tmp_path, result)


def test_a_reply_whose_content_is_the_json_object_itself_is_read(make_scene, tmp_path, monkeypatch) -> None:
    result, _ = _run(make_scene, tmp_path, monkeypatch, "openai", [("object", DESC, 0), ("object", GOOD, 0)])
    assert not result.provenance.fallback and result.intents, result.llm_error


def test_a_429_whose_error_is_a_bare_string_is_retried(make_scene, tmp_path, monkeypatch) -> None:
    result, server = _run(
        make_scene, tmp_path, monkeypatch, "gemini", [("429-string", "slow down", 0), (200, DESC, 0), (200, GOOD, 0)]
    )
    assert not result.provenance.fallback and len(server.requests) == 3, result.llm_error


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_a_slow_loris_server_cannot_hold_a_request_past_its_deadline(make_scene, tmp_path, monkeypatch, kind) -> None:
    import time

    started = time.perf_counter()
    script = [("drip", DESC, 0.2)] * 2  # ~100 bytes at 0.2 s: 20 s of reads, each well within the timeout
    result, _ = _run(make_scene, tmp_path, monkeypatch, kind, script, max_retries=1, timeout_s=1.0)
    assert time.perf_counter() - started < 8.0
    assert result.provenance.fallback and "no complete reply within 1 s" in result.llm_error, result.llm_error


@pytest.mark.parametrize("kind", ["gemini", "openai"])
def test_a_gzip_bomb_is_refused_while_it_is_decoded(make_scene, tmp_path, monkeypatch, kind) -> None:
    # 256 MB of reply in about 256 KB of gzip: the SDK's client would decode all of it before the size check
    result, server = _run(make_scene, tmp_path, monkeypatch, kind, [("gzip-bomb", "", 256)] * 3)
    assert result.provenance.fallback and result.intents  # the offline model stood in
    assert "decodes to over 1,048,576 bytes (gzip)" in result.llm_error
    assert len(server.requests) == 1  # a refused body is not retried
    assert server.requests[0]["headers"]["Accept-Encoding"] == "gzip, deflate"


def test_reply_bodies_are_decoded_within_the_bound() -> None:
    import gzip
    import zlib

    from song.errors import SongError
    from song.pipeline.intents.http import ReplyTooLarge, decode_bounded

    text = b'{"routines": []}' * 100
    assert decode_bounded(text, "", 4096) == text
    assert decode_bounded(gzip.compress(text), "gzip", 4096) == text
    assert decode_bounded(zlib.compress(text), "deflate", 4096) == text
    raw = zlib.compressobj(6, zlib.DEFLATED, -zlib.MAX_WBITS)
    assert (
        decode_bounded(raw.compress(text) + raw.flush(), "deflate", 4096) == text
    )  # raw deflate, as some servers send
    assert decode_bounded(gzip.compress(gzip.compress(text)), "gzip, gzip", 4096) == text
    with pytest.raises(ReplyTooLarge, match="decodes to over 1,000 bytes"):
        decode_bounded(gzip.compress(text), "gzip", 1000)
    with pytest.raises(SongError, match="unsupported Content-Encoding 'br'"):
        decode_bounded(text, "br", 4096)
    with pytest.raises(SongError, match="corrupt gzip body"):
        decode_bounded(b"\x1f\x8b not gzip", "gzip", 4096)
