"""The residual FCN of Fig. 4 and the input/output rotations that turn one FCN into several Q-maps.

One FCN maps an image batch ``(B, C, H, W)`` to one dense Q-map ``(B, H, W)``. It is two 7-layer
residual halves (§IV-B.1b): an encoder whose three 2x2 max-pools take the image to 1/8 of its
size, and a decoder whose three bilinear 2x upsamplings bring it back. Sizes that are not
multiples of 8 are zero-padded at the bottom/right on the way in and cropped on the way out.

Push directions are rotations of the input (Fig. 5): the same FCN sees the image rotated by
0 or 180 degrees and its Q-map is rotated back. 0 and 180 degrees are exact flips (nearest
sampling, nothing falls outside the image), so they need no interpolation or padding.
"""

from __future__ import annotations

import torch as th
import torch.nn.functional as F
from torch import nn

#: Default channel widths of the three resolution levels. Chosen for CPU training: a batch-32
#: gradient step of 80x120 maps costs ~0.35 s at 16-32-64 on two cores, ~1 s at 32-64-128.
DEFAULT_WIDTHS: tuple[int, int, int] = (16, 32, 64)
#: Total downsampling of the encoder (three 2x2 max-pools).
SIZE_MULTIPLE = 8
#: Rotations we can do exactly with flips.
SUPPORTED_ROTATIONS = (0, 180)


class ResidualBlock(nn.Module):
    """RB(i) of Fig. 4: two 3x3 convolutions with a skip connection (1x1 projection if widths differ)."""

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels, out_channels, 3, padding=1)
        self.conv2 = nn.Conv2d(out_channels, out_channels, 3, padding=1)
        self.skip = nn.Identity() if in_channels == out_channels else nn.Conv2d(in_channels, out_channels, 1)

    def forward(self, x: th.Tensor) -> th.Tensor:
        h = F.relu(self.conv1(x))
        return F.relu(self.conv2(h) + self.skip(x))


class ResidualFCN(nn.Module):
    """Fig. 4: image ``(B, C, H, W)`` float in [0, 1] -> Q-map ``(B, H, W)``.

    Encoder (7 conv layers, 3 max-pools): Conv(3, w1) MP RB(w1) MP RB(w1->w2) MP RB(w2->w3).
    Decoder (7 conv layers, 3 bilinear 2x upsamplings): RB(w3->w2) UP RB(w2->w1) UP RB(w1) Conv(1, 1) UP.
    Channels grow only after a pool, so the cost per level stays about flat (measured: half the
    time of growing them before the pool, for the same widths).
    The last 1x1 convolution is applied before the last upsampling: both are linear and bilinear
    weights sum to one, so the result is identical and the full-resolution work is one channel.
    """

    def __init__(self, in_channels: int, widths: tuple[int, int, int] = DEFAULT_WIDTHS) -> None:
        super().__init__()
        if len(widths) != 3 or min(widths) < 1:
            raise ValueError(f"widths must be three positive channel counts, got {widths!r}")
        w1, w2, w3 = (int(w) for w in widths)
        self.stem = nn.Conv2d(in_channels, w1, 3, padding=1)
        self.down1 = ResidualBlock(w1, w1)
        self.down2 = ResidualBlock(w1, w2)
        self.down3 = ResidualBlock(w2, w3)
        self.up1 = ResidualBlock(w3, w2)
        self.up2 = ResidualBlock(w2, w1)
        self.up3 = ResidualBlock(w1, w1)
        self.head = nn.Conv2d(w1, 1, 1)

    def forward(self, x: th.Tensor) -> th.Tensor:
        height, width = x.shape[-2:]
        pad_h, pad_w = (-height) % SIZE_MULTIPLE, (-width) % SIZE_MULTIPLE
        if pad_h or pad_w:
            x = F.pad(x, (0, pad_w, 0, pad_h))
        h = F.max_pool2d(F.relu(self.stem(x)), 2)
        h = F.max_pool2d(self.down1(h), 2)
        h = F.max_pool2d(self.down2(h), 2)
        h = self.down3(h)
        h = _upsample(self.up1(h))
        h = _upsample(self.up2(h))
        q = _upsample(self.head(self.up3(h)))
        return q[:, 0, :height, :width]


def _upsample(x: th.Tensor) -> th.Tensor:
    return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)


def rotate(images: th.Tensor, degrees: int) -> th.Tensor:
    """Rotate the last two dims by 0 or 180 degrees (exact: a flip of rows and columns)."""
    if degrees == 0:
        return images
    if degrees == 180:
        return th.flip(images, dims=(-2, -1))
    raise ValueError(f"rotation {degrees} is not supported; use one of {SUPPORTED_ROTATIONS}")

