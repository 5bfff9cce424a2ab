class Root2DConstraintSet:
    name = "root2d"

    def __init__(self, skeleton, frame_indices, smooth_root_2d, to_crop: bool = False, global_root_heading=None):
        assert len(smooth_root_2d) == len(frame_indices)
        self.skeleton = skeleton
        self.frame_indices = frame_indices
        self.smooth_root_2d = smooth_root_2d
        self.global_root_heading = global_root_heading
