"""Gaussian avatars: the asset format, skinning-weight transfer, the procedural generator and PLY import."""

from song.datasets.avatars.asset import (
    AvatarAsset,
    export_avatar_ply,
    import_avatar_ply,
    list_avatars,
    load_avatar,
    save_avatar,
)

__all__ = ["AvatarAsset", "export_avatar_ply", "import_avatar_ply", "list_avatars", "load_avatar", "save_avatar"]
