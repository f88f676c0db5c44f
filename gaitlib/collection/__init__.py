"""Collecting transition samples: library policies switched at random moments and phases (switch trials of
:mod:`gaitlib.meta.trials` with the ``random`` strategy), each outcome labelled, written chunk by chunk into a
transition file (:mod:`gaitlib.transitions`)."""

from gaitlib.collection.collector import CollectConfig, CollectProgress, CollectResult, collect

__all__ = ["CollectConfig", "CollectProgress", "CollectResult", "collect"]
