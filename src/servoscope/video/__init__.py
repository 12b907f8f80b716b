"""Video input (PyAV) and output."""

from .reader import Frame, VideoInfo, iter_frames, probe_video

__all__ = ["Frame", "VideoInfo", "iter_frames", "probe_video"]
