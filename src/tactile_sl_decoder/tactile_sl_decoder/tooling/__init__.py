"""Tooling around the pipeline: training data, evaluation, metrics, pictures.

Used by the CLI and tools/, never by the stages (extract, classify, decode, stereo, touch).
"""
