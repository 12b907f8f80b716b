"""Campaigns: the manifest, and running the whole identification."""

from .manifest import Campaign, TestSpec, load_campaign
from .runner import IdentificationResult, identify, track_campaign

__all__ = ["Campaign", "IdentificationResult", "TestSpec", "identify", "load_campaign", "track_campaign"]
