"""Grading: robot episodes in four modes, A* factors, difficulty split, manifest."""

from song.pipeline.grading.grade import GradingResult, count_turns, grade_run, split_difficulty, tercile_bins

__all__ = ["GradingResult", "count_turns", "grade_run", "split_difficulty", "tercile_bins"]
