"""The avatar pool a run binds from: a folder of ``*.avatar.npz`` assets, or the default procedural pool.

The default pool is generated on first use (deterministic for its seed, size and Gaussian count, with
Anny bodies where Anny is installed and procedural ones otherwise: the folder's name says which) into
``$SONG_CACHE_DIR/avatars/<key>/`` (``~/.cache/song`` when unset) and reused afterwards; it is never
committed to the repository. A ``pool.json`` written last marks a complete pool, so an interrupted
build is redone rather than trusted; concurrent builders write the same bytes atomically.
"""

from __future__ import annotations

import os
from pathlib import Path

from song.config import BindingConfig
from song.datasets.avatars.asset import list_avatars
from song.errors import ConfigError
from song.util import write_json_atomic

POOL_FILE = "pool.json"


def cache_root() -> Path:
    """``$SONG_CACHE_DIR``, else ``$XDG_CACHE_HOME/song``, else ``~/.cache/song``."""
    if os.environ.get("SONG_CACHE_DIR"):
        return Path(os.environ["SONG_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "song"


def default_pool_dir(cfg: BindingConfig) -> Path:
    """Where the default pool for these settings lives."""
    from song.datasets.avatars.generate import GENERATOR_VERSION, default_body

    key = f"{default_body()}-v{GENERATOR_VERSION}-seed{cfg.pool_seed}-n{cfg.pool_size}-g{cfg.n_gaussians}"
    return cache_root() / "avatars" / key


def ensure_pool(cfg: BindingConfig) -> list[Path]:
    """Asset files to bind from, sorted by name (builds the default pool when needed).

    Raises:
        ConfigError: ``avatars_dir`` is set but holds no assets.
    """
    if cfg.avatars_dir:
        folder = Path(cfg.avatars_dir).expanduser()
        assets = list_avatars(folder)
        if not assets:
            raise ConfigError(folder, "binding.avatars_dir", "no *.avatar.npz assets in this folder")
        return assets
    folder = default_pool_dir(cfg)
    if not (folder / POOL_FILE).exists():
        from song.datasets.avatars.generate import build_pool

        paths = build_pool(folder, cfg.pool_size, cfg.pool_seed, cfg.n_gaussians)
        write_json_atomic(folder / POOL_FILE, {"count": len(paths), "files": [p.name for p in paths]})
    return list_avatars(folder)
