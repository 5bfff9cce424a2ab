from kimodo.fake_device import tensor


class Root2DConstraintSet:
    name = "root2d"

    def __init__(self, skeleton, frame_indices, smooth_root_2d, to_crop: bool = False, global_root_heading=None):
        assert len(smooth_root_2d) == len(frame_indices)
        self.skeleton = skeleton
        self.frame_indices = frame_indices
        self.smooth_root_2d = smooth_root_2d
        self.global_root_heading = global_root_heading

    def update_constraints(self, data_dict: dict, index_dict: dict) -> None:
        data_dict["smooth_root_2d"].append(self.smooth_root_2d)
        index_dict["smooth_root_2d"].append(self.frame_indices)
        if self.global_root_heading is not None:
            data_dict["global_root_heading"].append(self.global_root_heading)
            index_dict["global_root_heading"].append(self.frame_indices)

    @classmethod
    def from_dict(cls, skeleton, dico: dict) -> "Root2DConstraintSet":
        """As Kimodo's: the data on the skeleton's device, the frame indices on the CPU."""
        device = skeleton.device if hasattr(skeleton, "device") else "cpu"
        heading = dico.get("global_root_heading")
        return cls(
            skeleton,
            frame_indices=tensor(dico["frame_indices"]),
            smooth_root_2d=tensor(dico["smooth_root_2d"], device=device),
            global_root_heading=None if heading is None else tensor(heading, device=device),
        )
