import types

MODEL_NAMES = {"kimodo-soma-rp": "nvidia/Kimodo-SOMA-RP-v1"}
_INFO = types.SimpleNamespace(display_name="Kimodo-SOMA-RP-v1", repo_id="nvidia/Kimodo-SOMA-RP-v1")


def get_model_info(short_key):
    return _INFO if short_key == "kimodo-soma-rp" else None


def get_short_key_from_display_name(display_name):
    return "kimodo-soma-rp" if display_name == _INFO.display_name else None


def resolve_model_name(name, default_family):
    """Partial, case-insensitive names within a family (the real one also knows versions and datasets)."""
    lowered = name.lower()
    for short, repo in MODEL_NAMES.items():
        if lowered in short or lowered in repo.lower():
            return short
    raise ValueError(f"Model '{name}' not found")
