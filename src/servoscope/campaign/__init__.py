"""Campaigns: the manifest, running the whole identification, and its result."""

from .compare import ResultComparison, compare_results
from .manifest import Campaign, TestSpec, load_campaign
from .result import IdentificationResult
from .runner import identify, track_campaign

__all__ = ["Campaign", "IdentificationResult", "ResultComparison", "TestSpec", "compare_results", "identify",
           "load_campaign", "track_campaign"]
