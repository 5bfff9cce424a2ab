"""Kimodo adapter against file-based stand-ins that behave like kimodo and huggingface_hub (fake_kimodo_pkg/)."""

from __future__ import annotations

import numpy as np
import pytest

from song.config import MotionConfig
from song.errors import StageError
from song.geometry.rotations import quat_angle, quat_identity, quat_to_matrix, yaw_of_matrix
from song.pipeline.motion.generators import make_generator
from song.pipeline.motion.kimodo import (
    CachedTextEncoder,
    KimodoGenerator,
    canonicalize,
    kimodo_availability,
    plan_segments,
    sanitize_prompt,
    store_prompt_embedding,
)
from song.pipeline.motion.stage import synthesize_motions
from song.pipeline.motion.synthetic import trajectory_from_profiles
from tests.pipeline.motion import fake_kimodo

torch = pytest.importorskip("torch")  # Kimodo is a torch model (the torch extra; dev installs it)
PROMPT = MotionConfig().prompt


def _vector(value: float = 1.0) -> np.ndarray:
    return np.full(fake_kimodo.LLM_DIM, value, dtype=np.float32)


@pytest.fixture
def fake(monkeypatch, tmp_path):
    fake_kimodo.install(monkeypatch, tmp_path)
    cache = tmp_path / "embeddings"
    store_prompt_embedding(cache, PROMPT, _vector())
    cfg = MotionConfig(kimodo_embedding_cache=str(cache), kimodo_max_frames=120, kimodo_steps=12, kimodo_batch_size=4)
    yield None, cfg
    fake_kimodo.cleanup()


def _plans():
    n = 90
    straight = trajectory_from_profiles(0, np.full(n, 1.0), np.zeros(n), start=(2.0, -1.0, 2.0))
    curve = trajectory_from_profiles(1, np.full(n, 0.8), np.full(n, 0.6), start=(-1.0, 3.0, -0.5))
    long = trajectory_from_profiles(2, np.full(300, 0.7), 0.3 * np.sin(np.arange(300) / 40), start=(0.0, 0.0, 1.0))
    return [straight, curve, long]


def test_availability_and_selection(fake):
    _, cfg = fake
    assert kimodo_availability(cfg) == ""
    generator, reason = make_generator(cfg)
    assert isinstance(generator, KimodoGenerator) and reason == ""


def test_what_kimodo_receives(fake):
    _, cfg = fake
    plans = _plans()
    KimodoGenerator(cfg).generate(plans, ["a", "b", "c"], [11, 12, 13])
    model = fake_kimodo.models()[0]
    batched, multi = model.calls
    # short tracks: one batched call, one constraint list per sample, the paper's prompt
    assert batched["prompts"] == [PROMPT, PROMPT] and batched["num_samples"] == 2
    assert batched["num_frames"] == [90, 90] and not batched["multi_prompt"]
    assert batched["steps"] == 12 and batched["post_processing"] is True and batched["return_numpy"] is True
    assert torch.equal(batched["first_heading_angle"], torch.zeros(2))
    assert batched["text_feat_shape"] == (2, 1, fake_kimodo.LLM_DIM)  # one pooled vector per prompt
    for group, plan in zip(batched["constraint_lst"], plans[:2], strict=True):
        (constraint,) = group
        root = constraint.smooth_root_2d
        assert root.dtype == torch.float32 and root.shape == (90, 2)
        assert torch.equal(constraint.frame_indices, torch.arange(90)) and constraint.frame_indices.device.type == "cpu"
        assert np.allclose(root[0].numpy(), 0.0)  # frame 0 at the origin
        heading = fake_kimodo.heading_from(constraint)
        assert abs(heading[0]) < 1e-6  # first heading faces +Z
        # θ = atan2(dx, dz) of the path agrees with the constrained heading
        d = np.diff(root.numpy().astype(np.float64), axis=0)
        assert np.abs(fake_kimodo.angle_diff(np.arctan2(d[:, 0], d[:, 1]), heading[:-1])).max() < 0.05
        assert np.allclose(
            np.linalg.norm(d, axis=1).sum(), np.linalg.norm(np.diff(plan.xy, axis=0), axis=1).sum(), rtol=1e-4
        )
    straight = batched["constraint_lst"][0][0].smooth_root_2d.numpy()
    assert np.abs(straight[:, 0]).max() < 1e-5 and straight[-1, 1] > 2.9  # straight ahead along +Z
    curve = batched["constraint_lst"][1][0].smooth_root_2d.numpy()
    assert curve[-1, 0] > 0.3  # a left (CCW) turn goes to Kimodo +X (the body's left)
    # the long track: multi-prompt, segments of at most kimodo_max_frames, one shared constraint list
    assert multi["multi_prompt"] and multi["num_samples"] == 1
    assert sum(multi["num_frames"]) == 300 and max(multi["num_frames"]) <= 120 and len(multi["prompts"]) == 3
    assert len(multi["constraint_lst"]) == 1 and multi["constraint_lst"][0].smooth_root_2d.shape == (300, 2)


def test_output_is_mapped_back_to_the_world(fake):
    _, cfg = fake
    plans = _plans()
    motions = KimodoGenerator(cfg).generate(plans, ["a", "b", "c"], [11, 12, 13])
    for motion, plan in zip(motions, plans, strict=True):
        assert motion.local_quats.shape == (plan.n_frames, 24, 4)
        yaw = yaw_of_matrix(quat_to_matrix(motion.local_quats[:, 0]))
        assert np.abs(fake_kimodo.angle_diff(yaw, plan.yaw)).max() < 1e-4
        # the fake's Kimodo-frame root bias comes back rotated into the world: ~3.6 cm from the plan
        err = np.linalg.norm(motion.root_pos[:, :2] - plan.xy, axis=1)
        assert np.allclose(err, np.hypot(*fake_kimodo.ROOT_OFFSET), atol=1e-4)
        assert np.allclose(motion.root_pos[:, 2], motion.rest_joints[0, 2], atol=1e-5)  # hips height rescaled
        # the fake body is T-posed: every non-root local rotation is the identity after retargeting
        assert quat_angle(motion.local_quats[:, 1:], quat_identity((plan.n_frames, 23))).max() < 1e-5
        info = motion.info
        assert info["name"] == "kimodo" and info["prompt"] == PROMPT and info["model"] == "kimodo-soma-rp"
    assert motions[2].info["segments"] == 3


def test_pipeline_aligns_kimodo_output(fake):
    _, cfg = fake
    plans = _plans()
    results = synthesize_motions(plans, ["a", "b", "c"], [1, 2, 3], cfg)
    for (motion, meta), plan in zip(results, plans, strict=True):
        assert meta["generator"]["name"] == "kimodo" and meta["generator"]["fallback"] is False
        assert meta["alignment"]["root_error_before_mean_m"] > 0.03
        assert meta["quality"]["root_error_mean_m"] < 0.005
        assert np.linalg.norm(motion.root_pos[:, :2] - plan.xy, axis=1).max() < 0.02


def test_missing_embedding_falls_back_in_auto_mode(fake, tmp_path):
    _, cfg = fake
    cfg = cfg.model_copy(update={"prompt": "A person is jogging", "generator": "auto"})
    results = synthesize_motions(_plans()[:1], ["a"], [1], cfg)
    meta = results[0][1]
    assert meta["generator"]["name"] == "procedural" and meta["generator"]["fallback"] is True
    assert "no cached embedding" in meta["generator"]["fallback_reason"]  # found before loading the model
    with pytest.raises(StageError, match="no cached embedding"):
        synthesize_motions(_plans()[:1], ["a"], [1], cfg.model_copy(update={"generator": "kimodo"}))


def test_cached_encoder_returns_pooled_vectors_and_canonical_frame():
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        store_prompt_embedding(folder, "a b", _vector(1.0))
        store_prompt_embedding(folder, "c", _vector(2.0)[None])  # (1, 4096) as LLM2Vec returns it
        feat, lengths = CachedTextEncoder(folder)(["a  b", "c"])  # whitespace is sanitised away
        one, length = CachedTextEncoder(folder)("c")
        with pytest.raises(ValueError, match="pooled"):
            store_prompt_embedding(folder, "d", np.ones((7, 16)))  # token embeddings are not what Kimodo uses
    assert feat.shape == (2, 1, fake_kimodo.LLM_DIM) and lengths == [1, 1] and float(feat[1].mean()) == 2.0
    assert one.shape == (1, fake_kimodo.LLM_DIM) and length == 1
    plan = trajectory_from_profiles(0, np.full(30, 1.0), np.zeros(30), start=(5.0, 5.0, np.pi / 2))
    canon = canonicalize(plan, plan.t)
    assert np.allclose(canon["root_2d"][:, 0], 0.0, atol=1e-12) and canon["root_2d"][-1, 1] > 0.9
    assert float(canon["yaw0"]) == pytest.approx(np.pi / 2)


PROMPTS = [
    " A person is    walking.",
    "someone go forward",
    "a person WALKS quickly!!  then stops",
    "...walks forward ,",
    "walks. turns around? sits down!",
    '"quoted" prompt"',
    "a",
    "   ",
    "ends with a bracket)",
]


def test_one_sanitiser_that_matches_kimodos(fake):
    from kimodo.sanitize import sanitize_texts

    assert [sanitize_prompt(p) for p in PROMPTS] == sanitize_texts(PROMPTS)
    assert sanitize_prompt("someone go forward") == "Someone go forward."
    assert sanitize_prompt("a person WALKS quickly") == "A person walks quickly."


def test_segments_keep_every_generated_window_within_the_limit():
    for n in (301, 600, 700, 1234, 3000):
        lengths = plan_segments(n, 300)
        windows = [lengths[0]] + [b + 5 + int(0.1 * a) for a, b in zip(lengths[:-1], lengths[1:], strict=False)]
        assert sum(lengths) == n and max(windows) <= 300
    assert plan_segments(300, 300) == [300]


def test_long_track_windows_and_base_step_cap(fake):
    _, cfg = fake
    cfg = cfg.model_copy(update={"kimodo_max_frames": 300, "kimodo_steps": 100})  # the fake's schedule has 50
    long = trajectory_from_profiles(0, np.full(700, 0.7), 0.2 * np.sin(np.arange(700) / 50), start=(0.0, 0.0, 0.0))
    (motion,) = KimodoGenerator(cfg).generate([long], ["a"], [5])
    (call,) = fake_kimodo.models()[0].calls
    assert call["multi_prompt"] and max(call["windows"]) <= 300 and sum(call["num_frames"]) == 700
    assert call["steps"] == fake_kimodo.BASE_STEPS and motion.info["denoising_steps"] == fake_kimodo.BASE_STEPS


def test_every_tensor_handed_to_kimodo_is_where_kimodo_wants_it(fake):
    """On a GPU model: frame indices on the CPU, constraint data on the model's device (Kimodo's from_dict).

    The stand-in's GPU refuses what CUDA refuses: its conditioning indexes the data with indices moved to
    the model's device, its post-processing indexes CPU buffers with the frame indices.
    """
    from kimodo.fake_device import FAKE_GPU, device_of

    _, cfg = fake
    motions = KimodoGenerator(cfg, device=FAKE_GPU).generate(_plans(), ["a", "b", "c"], [3, 4, 5])
    assert len(motions) == 3 and all(np.isfinite(m.root_pos).all() for m in motions)
    model = fake_kimodo.models()[0]
    assert model.device == FAKE_GPU
    handed = [c for call in model.calls for group in call["constraint_lst"] for c in np.atleast_1d(group)]
    assert len(handed) == 3
    for constraint in handed:
        assert device_of(constraint.frame_indices) == "cpu"
        assert (
            device_of(constraint.smooth_root_2d) == FAKE_GPU and device_of(constraint.global_root_heading) == FAKE_GPU
        )


def test_the_gpu_stand_in_refuses_constraint_data_left_on_the_cpu(fake):
    import torch
    from kimodo.constraints import Root2DConstraintSet
    from kimodo.fake_device import FAKE_GPU

    _, cfg = fake
    model = KimodoGenerator(cfg, device=FAKE_GPU).load()
    cpu = Root2DConstraintSet(model.skeleton, torch.arange(4), torch.zeros(4, 2), global_root_heading=torch.ones(4, 2))
    with pytest.raises(RuntimeError, match="same device as the indexed tensor"):
        model([PROMPT], [4], 12, constraint_lst=[[cpu]], num_samples=1)


def test_partial_model_names_resolve(fake):
    _, cfg = fake
    cfg = cfg.model_copy(update={"kimodo_model": "SOMA"})
    assert kimodo_availability(cfg) == ""
    (motion,) = KimodoGenerator(cfg).generate(_plans()[:1], ["a"], [3])
    assert motion.info["model"] == "kimodo-soma-rp"


def test_weights_from_the_hub_cache_and_no_download_ever(monkeypatch, tmp_path):
    fake_kimodo.install(monkeypatch, tmp_path, where="hf_cache")
    try:
        import huggingface_hub  # imported first, online: it read HF_HUB_OFFLINE=0 at import

        assert huggingface_hub.constants.HF_HUB_OFFLINE is False
        cache = tmp_path / "embeddings"
        store_prompt_embedding(cache, PROMPT, _vector())
        cfg = MotionConfig(kimodo_embedding_cache=str(cache), kimodo_max_frames=120, kimodo_steps=12)
        assert kimodo_availability(cfg) == ""
        (motion,) = KimodoGenerator(cfg).generate(_plans()[:1], ["a"], [3])
        assert motion.info["name"] == "kimodo" and huggingface_hub.DOWNLOADS == []
        # weights gone from the cache: the hub must refuse offline, never try a download
        for path in (tmp_path / "hf_cache").rglob("config.yaml"):
            path.unlink()
        from song.pipeline.motion import kimodo as adapter

        adapter._LOADED.clear()  # a fresh worker process: it has loaded nothing yet
        with pytest.raises(Exception, match="HF_HUB_OFFLINE|config.yaml"):
            KimodoGenerator(cfg).load()
        assert huggingface_hub.DOWNLOADS == []
    finally:
        fake_kimodo.cleanup()


def test_availability_names_what_is_missing(monkeypatch, tmp_path):
    fake_kimodo.install(monkeypatch, tmp_path, motion_correction=False)
    try:
        cache = tmp_path / "embeddings"
        cfg = MotionConfig(kimodo_embedding_cache=str(cache))
        assert "motion_correction" in kimodo_availability(cfg)
        cfg = cfg.model_copy(update={"kimodo_postprocess": False})
        assert "embedding" in kimodo_availability(cfg)
        store_prompt_embedding(cache, cfg.prompt, _vector())
        assert kimodo_availability(cfg) == ""
    finally:
        fake_kimodo.cleanup()


def test_the_model_is_loaded_once_per_process_not_once_per_scene(fake):
    _, cfg = fake
    for seed in (1, 2, 3):  # three scenes, each with its own generator (as the motion stage makes them)
        generator, reason = make_generator(cfg)
        assert reason == ""
        generator.generate(_plans()[:1], ["a"], [seed])
    assert len(fake_kimodo.models()) == 1 and len(fake_kimodo.models()[0].calls) == 3
