"""Read once, at import, like the real huggingface_hub.constants."""

import os

HF_HUB_OFFLINE = os.environ.get("HF_HUB_OFFLINE", "0").upper() in ("1", "ON", "YES", "TRUE")
HF_HUB_CACHE = os.environ.get("HF_HUB_CACHE", "")
