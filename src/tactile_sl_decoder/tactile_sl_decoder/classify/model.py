"""The LeNet-5-style glyph classifier in torch (training and reference inference).

18x18 grey patch -> conv 6@5x5 -> ReLU -> max-pool 2 -> conv 16@5x5 -> ReLU -> max-pool 2
(ceil mode, so the 3x3 map becomes 2x2 and no input pixel is ignored) -> FC 32 -> FC 64 ->
one logit per symbol. Patches are standardised per patch (zero mean, unit variance) before
the first layer, which removes the lighting level and contrast of the pad where the glyph
lies. ``numpy_forward`` in :mod:`tactile_sl_decoder.classify.classifier` computes the same function
without torch, for speed.
"""
from __future__ import annotations

import torch
from torch import nn

from tactile_sl_decoder.classify.classifier import LENET_ARCH, TINY_ARCH
from tactile_sl_decoder.contract import PATCH_SIZE


class GlyphNet(nn.Module):
    """LeNet-5 as the method describes it, sized for 18x18 patches."""

    def __init__(self, classes: int = 3) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(1, 6, 5)
        self.conv2 = nn.Conv2d(6, 16, 5)
        self.fc1 = nn.Linear(16 * 2 * 2, 32)
        self.fc2 = nn.Linear(32, 64)
        self.out = nn.Linear(64, classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits (N, classes) of standardised patches (N, 1, 18, 18)."""
        x = torch.max_pool2d(torch.relu(self.conv1(x)), 2)
        x = torch.max_pool2d(torch.relu(self.conv2(x)), 2, ceil_mode=True)
        x = torch.relu(self.fc1(x.flatten(1)))
        x = torch.relu(self.fc2(x))
        return self.out(x)


def standardise(patches: torch.Tensor) -> torch.Tensor:
    """(N, 18, 18) uint8/float -> (N, 1, 18, 18) float, zero mean and unit variance per patch."""
    x = patches.reshape(patches.shape[0], -1).float()
    x = x - x.mean(dim=1, keepdim=True)
    x = x / (x.std(dim=1, unbiased=False, keepdim=True) + 1.0)
    return x.reshape(-1, 1, PATCH_SIZE, PATCH_SIZE)


class GlyphNetTiny(nn.Module):
    """A right-sized net for three well separated shapes: about 15x fewer operations.

    18x18 patch (standardised) -> 2x2 average pool (9x9) -> conv ``channels``@3x3 -> ReLU ->
    max-pool 2 (ceil: 4x4) -> FC ``hidden`` -> ReLU -> one logit per symbol.  LeNet-5 was
    sized for the seed's 6,000 real samples; a patch spans one glyph spacing, so 9x9 still
    resolves a stroke, and one convolution layer tells a line, a circle and a triangle
    apart (held-out figures in data/classifier_card.md).
    """

    def __init__(self, classes: int = 3, channels: int = 16, hidden: int = 32) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(1, channels, 3)
        self.fc1 = nn.Linear(channels * 4 * 4, hidden)
        self.out = nn.Linear(hidden, classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits (N, classes) of standardised patches (N, 1, 18, 18)."""
        x = torch.nn.functional.avg_pool2d(x, 2)
        x = torch.max_pool2d(torch.relu(self.conv1(x)), 2, ceil_mode=True)
        x = torch.relu(self.fc1(x.flatten(1)))
        return self.out(x)


def make_model(arch: str, classes: int) -> nn.Module:
    """A fresh net of the architecture tagged ``arch`` (classify.classifier's tags)."""
    if arch == LENET_ARCH:
        return GlyphNet(classes)
    if arch == TINY_ARCH:
        return GlyphNetTiny(classes)
    raise ValueError(f"unknown classifier architecture {arch!r}")
