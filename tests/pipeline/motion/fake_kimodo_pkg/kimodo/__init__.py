"""Fake kimodo (see ../README.md)."""

from kimodo.model.load_model import MODELS, load_model  # noqa: F401

DEFAULT_MODEL = "kimodo-soma-rp"
AVAILABLE_MODELS = ["kimodo-soma-rp"]
