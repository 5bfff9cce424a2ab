"""Installs the file-based stand-ins of ``fake_kimodo_pkg/`` (kimodo, huggingface_hub, motion_correction).

See fake_kimodo_pkg/README.md for what they check. :func:`install` puts the folder first on
``sys.path`` with the weights either under ``CHECKPOINT_DIR`` or in the fake Hugging Face cache, and
removes every module it imported when the test ends.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

PACKAGES = Path(__file__).resolve().parent / "fake_kimodo_pkg"
NAMES = ("kimodo", "huggingface_hub", "motion_correction")
DISPLAY, REPO = "Kimodo-SOMA-RP-v1", "nvidia/Kimodo-SOMA-RP-v1"
ROOT_OFFSET = np.array([0.03, -0.02])  # as kimodo/fake_model.py
BASE_STEPS = 50
LLM_DIM = 4096


def _ours(name: str) -> bool:
    return any(name == top or name.startswith(top + ".") for top in NAMES)


def install(monkeypatch, tmp_path: Path, where: str = "checkpoint_dir", motion_correction: bool = True) -> None:
    """Make the fakes importable; weights in ``CHECKPOINT_DIR`` or the hub cache (``where="hf_cache"``)."""
    for name in [n for n in sys.modules if _ours(n)]:
        monkeypatch.delitem(sys.modules, name)
    root = tmp_path / "fake_site"
    root.mkdir(parents=True, exist_ok=True)
    for name in NAMES:
        if name != "motion_correction" or motion_correction:
            (root / name).symlink_to(PACKAGES / name, target_is_directory=True)
    monkeypatch.syspath_prepend(str(root))
    for var in ("HF_HUB_OFFLINE", "CHECKPOINT_DIR", "LOCAL_CACHE", "TEXT_ENCODER_MODE", "TEXT_ENCODER"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "hf_cache"))
    if where == "checkpoint_dir":
        folder = tmp_path / "checkpoints" / DISPLAY
        monkeypatch.setenv("CHECKPOINT_DIR", str(tmp_path / "checkpoints"))
    else:
        folder = tmp_path / "hf_cache" / REPO.replace("/", "--")
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "config.yaml").write_text("fake: true\n")


def cleanup() -> None:
    """Forget every fake module (call at teardown)."""
    for name in [n for n in sys.modules if _ours(n)]:
        del sys.modules[name]


def models() -> list:
    import kimodo

    return kimodo.MODELS


def heading_from(constraint) -> np.ndarray:
    cos_sin = constraint.global_root_heading.numpy()
    return np.arctan2(cos_sin[:, 1], cos_sin[:, 0])


def angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a - b + math.pi) % (2 * math.pi) - math.pi
