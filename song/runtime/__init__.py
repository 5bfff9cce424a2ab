"""Thin closed-loop runtime: replay, collisions, robot, metrics, policies, evaluation, Gymnasium env.

Reads a release through :mod:`song.datasets.bench` and poses avatars through :mod:`song.geometry`;
never imports :mod:`song.pipeline`.
"""
