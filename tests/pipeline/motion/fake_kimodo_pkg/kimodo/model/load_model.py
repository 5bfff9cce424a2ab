import importlib
import os
from pathlib import Path

from huggingface_hub import snapshot_download  # imported with the module, as in Kimodo

from kimodo.model import registry

TEXT_ENCODER_PRESETS = {"llm2vec": {"target": "kimodo.model.LLM2VecEncoder", "kwargs": {}}}
MODELS: list = []


def _resolve_hf_model_path(modelname):
    repo_id = registry.MODEL_NAMES[modelname]
    if os.environ.get("LOCAL_CACHE", "False").lower() != "true":
        return Path(snapshot_download(repo_id=repo_id))  # checks online no matter what
    try:
        return Path(snapshot_download(repo_id=repo_id, local_files_only=True))
    except Exception:
        return Path(snapshot_download(repo_id=repo_id))


def load_model(modelname=None, device=None, eval_mode=True, default_family="Kimodo", return_resolved_name=False):
    from kimodo.fake_model import Model

    if modelname not in registry.MODEL_NAMES:
        modelname = registry.resolve_model_name(modelname, default_family)
    assert os.environ.get("TEXT_ENCODER_MODE") == "local", "the adapter must not reach a text-encoder server"
    root = os.environ.get("CHECKPOINT_DIR")
    if root:
        folder = Path(root) / registry.get_model_info(modelname).display_name
        if not folder.exists():
            folder = _resolve_hf_model_path(modelname)
    else:
        folder = _resolve_hf_model_path(modelname)
    if not (folder / "config.yaml").exists():
        raise FileNotFoundError(folder / "config.yaml")
    preset = TEXT_ENCODER_PRESETS[os.environ["TEXT_ENCODER"]]
    module, _, cls = preset["target"].rpartition(".")
    encoder = getattr(importlib.import_module(module), cls)(**preset["kwargs"])
    model = Model(encoder, device)
    MODELS.append(model)
    return (model, modelname) if return_resolved_name else model
