"""Camera models: intrinsics, Brown–Conrady lens distortion, point (un)distortion."""

from .model import CameraModel

__all__ = ["CameraModel"]
