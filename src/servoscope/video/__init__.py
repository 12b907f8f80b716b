"""Video input (PyAV), image sequences and high-speed files, and output."""

from .frame_source import frame_source, is_frame_source
from .info import describe_footage
from .reader import Frame, VideoInfo, iter_frames, probe_video

__all__ = ["Frame", "VideoInfo", "iter_frames", "probe_video", "frame_source", "is_frame_source", "describe_footage"]
