"""A hub with a local cache folder ($HF_HUB_CACHE/<repo id>/) that records every download attempt."""

from pathlib import Path

from huggingface_hub import constants

DOWNLOADS: list[str] = []  # repo ids a download was attempted for (a real hub would go online)


class OfflineModeIsEnabled(ConnectionError):
    pass


class LocalEntryNotFoundError(FileNotFoundError):
    pass


def _folder(repo_id: str) -> Path:
    return Path(constants.HF_HUB_CACHE) / repo_id.replace("/", "--")


def try_to_load_from_cache(repo_id: str, filename: str):
    path = _folder(repo_id) / filename
    return str(path) if path.is_file() else None


def snapshot_download(repo_id: str, local_files_only: bool = False) -> str:
    if (_folder(repo_id) / "config.yaml").is_file():
        return str(_folder(repo_id))
    if local_files_only:
        raise LocalEntryNotFoundError(repo_id)
    if constants.HF_HUB_OFFLINE:
        raise OfflineModeIsEnabled(f"cannot download {repo_id}: HF_HUB_OFFLINE is set")
    DOWNLOADS.append(repo_id)
    raise ConnectionError(f"tried to download {repo_id}")
