"""Sampling an image at moved positions: the warps of the light effects.

Positions are in ``grid_sample``'s normalised coordinates with
``align_corners=True``: pixel centres ``0 .. W - 1`` (``0 .. H - 1``) map
to ``-1 .. 1``. Samples are bilinear, with the border value repeated
outside the image.
"""
import torch
import torch.nn.functional as F

__all__ = []

# Pixel-steps warped at once: 16 MiB per (K, H, W, 2) float32 grid, small
# enough that the allocator reuses its temporaries instead of mapping fresh
# pages for each block (which costs more than the warping).
_WARP_PIXEL_STEPS = 1 << 21


def warp_block_steps(max_steps: int, height: int, width: int) -> int:
    """Steps a light that warps ``height x width`` frames makes at once."""
    return max(1, min(max_steps, _WARP_PIXEL_STEPS // (height * width)))


def pixel_scale(height: int, width: int) -> tuple:
    """``(sx, sy)``: normalised units per pixel along x and y."""
    return 2 / max(width - 1, 1), 2 / max(height - 1, 1)


def identity_grid(height: int, width: int, device) -> torch.Tensor:
    """``(H, W, 2)`` float32 normalised ``(x, y)`` of each pixel."""
    ys, xs = torch.meshgrid(
        torch.linspace(-1, 1, height, device=device),
        torch.linspace(-1, 1, width, device=device), indexing='ij')
    return torch.stack([xs, ys], dim=-1)


def affine_grid(theta: torch.Tensor, height: int,
                width: int) -> torch.Tensor:
    """``(K, H, W, 2)`` normalised positions ``theta[k] @ (x, y, 1)``.

    As ``F.affine_grid(theta, (K, 1, H, W), align_corners=True)``, but as
    sums of a row and a column term (the map is separable), not a batched
    matrix product with an inner dimension of 3.

    Args:
        theta: ``(K, 2, 3)`` float32 affine maps in normalised coordinates.
    """
    xs = torch.linspace(-1, 1, width, device=theta.device)
    ys = torch.linspace(-1, 1, height, device=theta.device)
    grid = torch.empty((theta.shape[0], height, width, 2),
                       device=theta.device)
    for axis in range(2):
        row = theta[:, axis, 0, None] * xs + theta[:, axis, 2, None]
        column = theta[:, axis, 1, None] * ys
        torch.add(row[:, None, :], column[:, :, None], out=grid[..., axis])
    return grid


def sample(image: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """``(H, W)`` image sampled at ``(K, H', W', 2)`` normalised positions:
    ``(K, H', W')``."""
    steps, height, width = grid.shape[:3]
    # One batch of K * H' rows: no K copies of the image.
    rows = grid.reshape(1, steps * height, width, 2)
    source = image.to(torch.float32)[None, None]
    return F.grid_sample(source, rows, mode='bilinear',
                         padding_mode='border',
                         align_corners=True).view(steps, height, width)
