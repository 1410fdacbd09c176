"""Synthetic survey scenes with exact truth (the demo's default data and the tests' truth)."""

from .scene import KINDS, Scene, make_scene

__all__ = ["KINDS", "Scene", "make_scene"]
