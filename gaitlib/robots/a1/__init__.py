"""The Unitree A1: its MJCF and its constants module."""

from gaitlib.robots.a1 import constants

__all__ = ["constants"]
